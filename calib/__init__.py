"""The calibrations a session needs before its streams mean anything, apart from the clocks.

The indenter's marker cluster as a rigid body (:mod:`calib.rigid`), its tip by pivot
calibration (:mod:`calib.pivot`), the force sensor's tare and 6x6 matrix
(:mod:`calib.force_tare`), and the phantom's rest plane (:mod:`calib.rest_plane`). Sync uses
them on every session; each is plain math, arrays in and arrays out.
"""

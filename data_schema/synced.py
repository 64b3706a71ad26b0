"""``X.h5`` from ``pipeline sync``: one synchronised record per press, on the mocap clock.

Each press ``presses/<NNN>`` (NNN = 000, 001, ... in time order) holds the mocap frames from a
margin before contact onset to a margin after release, so the unloaded start state is there:
``time_ns`` (mocap clock), ``points`` = the 25 phantom markers in session.toml order and the
indenter tip as the 26th point (lab frame), the force and torque in the force sensor's own
frame, as the ATI calibration matrix gives them, resampled onto the frame times (no rotation is
applied: that frame is not related to the axes of ``calibration/cluster_body``, which are the
principal axes of the marker cluster), the force magnitude, the tip's depth into the surface,
and quality bits per point (``QUALITY_BITS``) and per force sample (``FORCE_BITS``). Group
attributes give the location id, repeat number, the onset/peak/release frame indices within
the press (release is one past the last loaded frame), ``points_missing_throughout``
(indices of points with no sample from onset to release: never filled in), and the re-tare:
``rest_force_n`` and ``rest_torque_nm`` (2, 3), the sensor's rest reading (after the tare at
the start of the log) next to the press at onset and at release; the straight line between
them was subtracted from the press's force and torque (bias creep, tool weight).

The ``presses`` group's attribute ``cut_off`` counts presses left out because the end of the
mocap recording or of the force log cut them off (onset or release unknown).

``calibration/`` holds what sync measured, with its uncertainty: the cluster shape and tip
offset (pivot calibration), the force bias and tare interval at the start of the log, the rest
surface plane used for depth, and as attributes the clock model
(``t_logger = offset + (1 + drift) t_mocap``) and how it was found (``trigger``, ``data``, or
``shared`` when the force came through the mocap's analog board: offset and drift exactly 0).
Root attribute ``calibration`` repeats all of it as JSON; its ``clock`` says which ``policy``
applied and ``why`` (and has a ``note`` when ``--clock auto`` fell back from an unusable trigger
to the data).

Version 1.1 added ``rest_force_n``, ``rest_torque_nm`` and ``presses.cut_off``.
"""

from data_schema.hdf5 import Dataset, H5Schema

QUALITY_BITS = {"filled": 1, "missing": 2, "poor_fit": 4}
FORCE_BITS = {"outside_log": 1, "over_range": 2}

CLOCK_ATTRS = ("clock_method", "clock_offset_s", "clock_offset_sd_s", "clock_drift_ppm",
               "clock_drift_sd_ppm", "clock_rms_s", "clock_n")
PRESS_ATTRS = ("location", "repeat", "onset_index", "peak_index", "release_index",
               "onset_ns", "release_ns", "rest_force_n", "rest_torque_nm")

SYNCED = H5Schema(
    name="phantom.synced",
    version="1.1",
    root_attrs=("provenance", "source", "calibration", "quality_bits", "force_bits",
                "units_length", "units_force", "units_time", "rate_hz"),
    doc=__doc__ or "",
    group_attrs={"presses": ("cut_off",), "presses/*": PRESS_ATTRS,
                 "calibration": CLOCK_ATTRS + ("tip_rms_m", "tip_rotation_spread_deg")},
    datasets=(
        Dataset("point_names", "str", (26,), doc="25 phantom markers, then 'tip'"),
        Dataset("calibration/cluster_body", "f8", ("M", 3), "m",
                doc="indenter markers in the body frame (defines the frame)"),
        Dataset("calibration/tip_body", "f8", (3,), "m", doc="tip offset in the body frame"),
        Dataset("calibration/force_bias", "f8", (6,), doc="tare of the raw channels"),
        Dataset("calibration/surface_point", "f8", (3,), "m",
                doc="a point of the phantom markers' rest plane (depth 0)"),
        Dataset("calibration/surface_normal", "f8", (3,), "1",
                doc="unit normal of the rest plane, out of the phantom"),
        Dataset("locations/centre", "f8", ("L", 3), "m",
                doc="mean tip contact point of each location"),
        Dataset("presses/*/time_ns", "i8", ("T",), "ns", doc="mocap clock"),
        Dataset("presses/*/points", "f8", ("T", 26, 3), "m", doc="NaN where missing"),
        Dataset("presses/*/force", "f8", ("T", 3), "N",
                doc="force sensor frame (not the cluster_body axes)"),
        Dataset("presses/*/torque", "f8", ("T", 3), "N*m", required=False, doc="sensor frame"),
        Dataset("presses/*/force_magnitude", "f8", ("T",), "N"),
        Dataset("presses/*/depth", "f8", ("T",), "m",
                doc="tip below the rest plane along its normal (positive into the phantom)"),
        Dataset("presses/*/quality", "u1", ("T", 26), doc="bitmask, see QUALITY_BITS"),
        Dataset("presses/*/force_quality", "u1", ("T",), doc="bitmask, see FORCE_BITS"),
    ),
)

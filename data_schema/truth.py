"""``truth.h5`` from ``pipeline synth``: what really happened in a synthetic session.

Everything is SI (m, N, N*m, s, V) in the mocap lab frame unless a name says otherwise; time
is on the mocap clock (0 at the first frame) unless it is ``logger/time_s``.

Clock convention (the one ``sync.clock`` uses): a true event at mocap time ``t_m`` (s) is
stamped by the force logger at ``t_f = clock/offset_s + (1 + clock/drift_ppm * 1e-6) * t_m``,
``t_f`` being the force file's time column (s).

Points are the N phantom markers (session.toml order, ``point_names``) and the indenter tip as
the last: N1 = N + 1 points (26 for the default twin's 25 markers); ``mocap/visible`` has the
N phantom markers, then the 4 indenter markers (N4 = N + 4). The sensor frame has the indenter
body frame's axes (``indenter/markers`` define that frame: origin at their centroid, z along
the shaft from the tip to the handle); ``force/sensor`` is the force the phantom exerts on the
tip, seen by the sensor (positive z when pressing), without the tool's weight; ``force/lab``
is the force the indenter exerts on the phantom.

``states`` are the true static states at every 0.5 N of each press's loading phase (step 0 is
the untouched surface at contact), exactly as the phantom model solved them.

``phantom/size`` is the block; ``inclusions`` are spheres of a stiffer (or softer) silicone
(their centres in the lab, and where they were asked: ``footprint``, on ``[0, L] x [0, W]``
from the block's corner of smallest x and y, the corner the states' phantom frame puts at its
origin, and ``depth``, the centre's below the rest surface), ``layers`` the top layer (from the
rest surface down ``thickness``); each ``ratio`` is the silicone's stiffness over the block's.
A block without them has none (I = 0, Y = 0).

Version 1.1: any number of phantom markers (a 1.0 file has 25). Version 1.2: the block's size,
its inclusions and layers (a 1.1 file has none of them: a uniform block of unrecorded size,
which :func:`read_regions` reads as no inclusion and no layer).
"""

from __future__ import annotations

from pathlib import Path

import numpy as np

from data_schema.hdf5 import Dataset, H5Schema, read_h5

CLOCK_DOC = ("a true event at mocap time t_m (s) is stamped by the force logger at "
             "t_f = offset_s + (1 + drift_ppm * 1e-6) * t_m, t_f in the force file's time "
             "column (s)")

TRUTH = H5Schema(
    name="phantom.truth",
    version="1.2",
    root_attrs=("provenance", "seed", "rate_hz", "logger_rate_hz", "clock_convention",
                "units_length", "units_force", "units_time", "noise_model"),
    doc=__doc__ or "",
    datasets=(
        Dataset("point_names", "str", ("N1",), doc="the N phantom markers, then 'tip'"),
        Dataset("mocap/time_s", "f8", ("T",), "s", doc="mocap frame times"),
        Dataset("mocap/points", "f8", ("T", "N1", 3), "m", doc="noise-free markers + tip"),
        Dataset("mocap/cluster", "f8", ("T", 4, 3), "m", doc="noise-free indenter markers"),
        Dataset("mocap/body_origin", "f8", ("T", 3), "m", doc="indenter body-frame origin"),
        Dataset("mocap/body_rotation", "f8", ("T", 3, 3), "1", doc="body -> lab"),
        Dataset("mocap/visible", "b1", ("T", "N4"), "1",
                doc="marker samples present in the 3D export (N phantom, then 4 indenter)"),
        Dataset("mocap/press", "i4", ("T",), "1", doc="press in contact, -1 when none"),
        Dataset("force/magnitude", "f8", ("T",), "N", doc="contact force at mocap frames"),
        Dataset("force/lab", "f8", ("T", 3), "N", doc="force on the phantom, lab frame"),
        Dataset("force/sensor", "f8", ("T", 3), "N", doc="force on the tip, sensor frame"),
        Dataset("force/torque_sensor", "f8", ("T", 3), "N*m",
                doc="contact torque about the sensor origin, sensor frame"),
        Dataset("logger/time_s", "f8", ("L",), "s", doc="force log time column (logger clock)"),
        Dataset("logger/mocap_time_s", "f8", ("L",), "s", doc="the same samples, mocap clock"),
        Dataset("logger/force", "f8", ("L", 3), "N", doc="contact force on the tip, sensor"),
        Dataset("logger/torque", "f8", ("L", 3), "N*m", doc="contact torque, sensor frame"),
        Dataset("logger/tool_force", "f8", ("L", 3), "N",
                doc="weight of the tool below the sensor, sensor frame (also logged)"),
        Dataset("clock/offset_s", "f8", (), "s", doc=CLOCK_DOC),
        Dataset("clock/drift_ppm", "f8", (), "ppm", doc=CLOCK_DOC),
        Dataset("calibration/matrix", "f8", (6, 6), "N/V,N*m/V",
                doc="wrench = matrix @ (volts - bias), rows Fx..Tz"),
        Dataset("calibration/bias", "f8", (6,), "V", doc="gauge bias at logger time 0"),
        Dataset("calibration/bias_drift", "f8", (6,), "V/s", doc="linear creep of the bias"),
        Dataset("calibration/quantum", "f8", (), "V", doc="logger count"),
        Dataset("calibration/noise", "f8", (), "V", doc="white noise sd per gauge"),
        Dataset("trigger/mocap_time_s", "f8", ("K",), "s", required=False,
                doc="rising edges of the sync pulses, mocap clock"),
        Dataset("trigger/logger_time_s", "f8", ("K",), "s", required=False,
                doc="the same edges, logger clock"),
        Dataset("indenter/markers", "f8", (4, 3), "m", doc="cluster markers, body frame"),
        Dataset("indenter/tip", "f8", (3,), "m", doc="tip offset, body frame"),
        Dataset("indenter/sensor", "f8", (3,), "m", doc="sensor origin, body frame"),
        Dataset("indenter/marker_names", "str", (4,)),
        Dataset("phantom/to_lab", "f8", (4, 4), "m",
                doc="homogeneous transform phantom frame (bottom centre, z up) -> lab"),
        Dataset("phantom/rest_points", "f8", ("N", 3), "m", doc="markers untouched, lab"),
        Dataset("phantom/shape_to_lab", "f8", (4, 4), "m", required=False,
                doc="a curved twin: its shape's frame (the phantom frame) -> lab"),
        Dataset("phantom/rest_surface", "f8", ("NX", "NY", 3), "m", required=False,
                doc="a curved twin: the top surface's lattice nodes untouched, lab"),
        Dataset("presses/normal", "f8", ("P", 3), "1", required=False,
                doc="a curved twin: the surface's outward normal where each press touched, lab"),
        Dataset("mocap/depth", "f8", ("T",), "m", required=False,
                doc="a curved twin: the tip below its press's untouched contact point along "
                    "that normal; NaN outside presses"),
        Dataset("phantom/size", "f8", (3,), "m", required=False,
                doc="the block: L along its +x, W, thickness (1.2)"),
        Dataset("inclusions/centre", "f8", ("I", 3), "m", required=False,
                doc="sphere centres, lab (1.2)"),
        Dataset("inclusions/footprint", "f8", ("I", 2), "m", required=False,
                doc="centres on the footprint [0, L] x [0, W] (1.2)"),
        Dataset("inclusions/depth", "f8", ("I",), "m", required=False,
                doc="centres below the rest surface (1.2)"),
        Dataset("inclusions/radius", "f8", ("I",), "m", required=False, doc="(1.2)"),
        Dataset("inclusions/ratio", "f8", ("I",), "1", required=False,
                doc="stiffness over the block's (1.2)"),
        Dataset("layers/thickness", "f8", ("Y",), "m", required=False,
                doc="from the rest surface down (1.2)"),
        Dataset("layers/ratio", "f8", ("Y",), "1", required=False,
                doc="stiffness over the block's (1.2)"),
        Dataset("locations/contact", "f8", ("C", 3), "m", doc="untouched contact points"),
        Dataset("locations/node", "i4", ("C", 2), "1", doc="top lattice node (i, j)"),
        Dataset("presses/location", "i4", ("P",), "1"),
        Dataset("presses/repeat", "i4", ("P",), "1"),
        Dataset("presses/direction", "f8", ("P", 3), "1", doc="unit press direction, lab"),
        Dataset("presses/fmax", "f8", ("P",), "N", doc="planned peak force (no tremor)"),
        Dataset("presses/start_frame", "i8", ("P",), "1", doc="first frame in contact"),
        Dataset("presses/peak_frame", "i8", ("P",), "1", doc="first frame at fmax"),
        Dataset("presses/end_frame", "i8", ("P",), "1", doc="last frame in contact"),
        Dataset("presses/times_s", "f8", ("P", 8), "s",
                doc="move, hover, approach, contact, peak, hold end, released, retracted"),
        Dataset("states/points", "f8", ("S", "N1", 3), "m", doc="static markers + tip"),
        Dataset("states/force", "f8", ("S",), "N", doc="0.5 N * step"),
        Dataset("states/force_vector", "f8", ("S", 3), "N", doc="on the phantom, lab"),
        Dataset("states/step", "i4", ("S",), "1"),
        Dataset("states/press", "i4", ("S",), "1"),
        Dataset("states/location", "i4", ("S",), "1"),
        Dataset("states/time_s", "f8", ("S",), "s",
                doc="when the loading force first reaches the state's force"),
        Dataset("pivot/point", "f8", (3,), "m", doc="the divot (tip), pivot recording's lab"),
        Dataset("pivot/time_s", "f8", ("Q",), "s"),
        Dataset("pivot/cluster", "f8", ("Q", 4, 3), "m", doc="noise-free indenter markers"),
        Dataset("pivot/rotation", "f8", ("Q", 3, 3), "1", doc="body -> lab"),
    ),
)

# the inclusions' and layers' datasets, each with its shape when there are none
REGIONS = {"inclusions/centre": (0, 3), "inclusions/footprint": (0, 2), "inclusions/depth": (0,),
           "inclusions/radius": (0,), "inclusions/ratio": (0,), "layers/thickness": (0,),
           "layers/ratio": (0,)}


def read_regions(path: str | Path) -> dict[str, np.ndarray]:
    """The inclusions and layers of a ``truth.h5`` (validated), by dataset path; a file from
    before 1.2 (a uniform block) gives each with no rows."""
    arrays, _ = read_h5(path, TRUTH, REGIONS)
    return {p: arrays.get(p, np.zeros(shape)) for p, shape in REGIONS.items()}

"""``X.h5`` from ``pipeline sync``: one synchronised record per press, on the mocap clock.

Each press ``presses/<NNN>`` (NNN = 000, 001, ... in time order) holds the mocap frames from a
margin before contact onset to a margin after release, so the unloaded start state is there:
``time_ns`` (mocap clock), ``points`` = the N phantom markers in session.toml order and the
indenter tip as the last point (lab frame; ``point_names`` names them, N >= 4), the force and
torque in the force sensor's own frame, as the ATI calibration matrix gives them, resampled
onto the frame times (no rotation is applied: that frame is not related to the axes of
``calibration/cluster_body``, which are the principal axes of the marker cluster), the force
magnitude, the tip's depth into the surface, and quality bits per point (``QUALITY_BITS``) and
per force sample (``FORCE_BITS``). Group attributes give the location id, repeat number, the
onset/peak/release frame indices within the press (release is one past the last loaded frame),
``points_missing_throughout`` (indices of points with no sample from onset to release: never
filled in), and the re-tare: ``rest_force_n`` and ``rest_torque_nm`` (2, 3), the sensor's rest
reading (after the tare at the start of the log) next to the press at onset and at release; the
straight line between them was subtracted from the press's force and torque (bias creep, tool
weight).

The ``presses`` group's attribute ``cut_off`` counts presses left out because the end of the
mocap recording or of the force log cut them off (onset or release unknown), and ``in_holes``
those left out because a hole in a stream touched them (1.4). Root attribute ``holes`` (JSON,
1.4) lists each hole: its ``stream`` (``mocap`` or ``force``) and file (``source``), the samples
``lost`` and its ``length_s``, where it starts on the stream's own clock (``after_s``) and on
the mocap's (``at_s``), whether it was ``bridged`` (at most 2 samples, a whole number of
periods: a straight line across it, no press left out), the frames ``[first, last + 1)`` it
reaches (its lost frames, or the frames whose force was resampled from its edge; null when
none) and the presses it cost (``presses_left_out``: each one's onset and release, s on the
mocap clock).

``calibration/`` holds what sync measured, with its uncertainty: the cluster shape and tip
offset (pivot calibration), the force bias and tare interval at the start of the log, the rest
surface plane used for depth, and as attributes the clock model
(``t_logger = offset + (1 + drift) t_mocap``) and how it was found (``trigger``, ``data``, or
``shared`` when the force came through the mocap's analog board: offset and drift exactly 0).
Root attribute ``calibration`` repeats all of it as JSON; its ``clock`` says which ``policy``
applied and ``why`` (and has a ``note`` when ``--clock auto`` fell back from an unusable trigger
to the data).

Force bits: ``outside_log`` (the frame lies outside the force log), ``over_range`` (beyond
the sensor's rated load on some axis, from the calibration), ``saturated`` (made of gauge
voltages on the amplifier's rail: the force there is clipped, not measured), ``in_hole`` (1.4:
in a hole of the force log, or resampled from its edge). Extract leaves out every press with
``over_range`` or ``saturated`` between onset and release. Quality bit ``lost`` (1.4): the
mocap never recorded the frame (a hole); sync leaves out the presses a hole touches, and a
press's margins stop at a hole.

Root attribute ``phantom`` (JSON, from session.toml's ``[phantom]`` table) says how extract
builds the phantom frame: the footprint's size, its in-plane +x axis and anchor, and for a
curved phantom its shape (:mod:`data_schema.shape`).

A curved phantom (1.5) has no rest plane: sync registers the markers to its shape and stores
``calibration/to_shape`` (4, 4), the lab -> shape frame transform extract uses as the phantom
frame, and ``calibration/marker_residual`` (N,), each marker's rest distance off the surface
less its radius (NaN: never seen). ``surface_point`` and ``surface_normal`` are then the shape
frame's origin and +z in the lab, and each press's ``depth`` runs along the surface's outward
normal ``touch_normal`` from the point ``touch`` where its tip touched (both lab, (3,)).

Version 1.1 added ``rest_force_n``, ``rest_torque_nm`` and ``presses.cut_off``; 1.2 the
``saturated`` force bit (a 1.1 file simply never sets it); 1.3 any number of phantom markers
and the ``phantom`` attribute (a 1.2 file has 25 markers and the paper's 100 mm square); 1.4
the holes (``lost``, ``in_hole``, ``presses.in_holes``, ``holes``; absent from older files);
1.5 a curved phantom's registration (absent for a flat one).
"""

from pathlib import Path

import h5py
import numpy as np

from core.errors import BadInput
from data_schema.hdf5 import Dataset, H5Schema, h5_reading, validate_h5
from data_schema.phantom import MIN_MARKERS

QUALITY_BITS = {"filled": 1, "missing": 2, "poor_fit": 4, "lost": 8}
FORCE_BITS = {"outside_log": 1, "over_range": 2, "saturated": 4, "in_hole": 8}

CLOCK_ATTRS = ("clock_method", "clock_offset_s", "clock_offset_sd_s", "clock_drift_ppm",
               "clock_drift_sd_ppm", "clock_rms_s", "clock_n")
PRESS_ATTRS = ("location", "repeat", "onset_index", "peak_index", "release_index",
               "onset_ns", "release_ns", "rest_force_n", "rest_torque_nm")

LAB_M = 50.0         # no marker of a mocap volume lies this far from its origin
BODY_M = 1.0         # no indenter marker or tip lies this far from the cluster's origin
FORCE_N = 1000.0     # beyond any force sensor pressing a phantom (a Nano17 saturates ~70 N)
TORQUE_NM = 100.0

SYNCED = H5Schema(
    name="phantom.synced",
    version="1.5",
    root_attrs=("provenance", "source", "calibration", "quality_bits", "force_bits",
                "units_length", "units_force", "units_time", "rate_hz"),
    doc=__doc__ or "",
    fixed_attrs={"units_length": "m", "units_force": "N", "units_time": "ns"},
    group_attrs={"presses": ("cut_off",), "presses/*": PRESS_ATTRS,
                 "calibration": CLOCK_ATTRS + ("tip_rms_m", "tip_rotation_spread_deg")},
    datasets=(
        Dataset("point_names", "str", ("P",), doc="the N phantom markers, then 'tip'"),
        Dataset("calibration/cluster_body", "f8", ("M", 3), "m", finite=True, limit=BODY_M,
                doc="indenter markers in the body frame (defines the frame)"),
        Dataset("calibration/tip_body", "f8", (3,), "m", finite=True, limit=BODY_M,
                doc="tip offset in the body frame"),
        Dataset("calibration/force_bias", "f8", (6,), finite=True,
                doc="tare of the raw channels"),
        Dataset("calibration/surface_point", "f8", (3,), "m", finite=True, limit=LAB_M,
                doc="a point of the phantom markers' rest plane (depth 0); a curved "
                    "phantom's: its shape frame's origin"),
        Dataset("calibration/surface_normal", "f8", (3,), "1", finite=True,
                doc="unit normal of the rest plane, out of the phantom; a curved phantom's: "
                    "its shape frame's +z"),
        Dataset("calibration/to_shape", "f8", (4, 4), required=False, finite=True,
                doc="a curved phantom: lab -> its shape's frame (the phantom frame)"),
        Dataset("calibration/marker_residual", "f8", ("N",), "m", required=False,
                limit=LAB_M, doc="a curved phantom: each marker's rest distance off the "
                                 "registered surface, less its radius; NaN never seen"),
        Dataset("locations/centre", "f8", ("L", 3), "m", finite=True, limit=LAB_M,
                doc="mean tip contact point of each location"),
        Dataset("presses/*/time_ns", "i8", ("T",), "ns", doc="mocap clock"),
        Dataset("presses/*/points", "f8", ("T", "P", 3), "m", limit=LAB_M,
                doc="NaN where missing"),
        Dataset("presses/*/force", "f8", ("T", 3), "N", finite=True, limit=FORCE_N,
                doc="force sensor frame (not the cluster_body axes)"),
        Dataset("presses/*/torque", "f8", ("T", 3), "N*m", required=False, finite=True,
                limit=TORQUE_NM, doc="sensor frame"),
        Dataset("presses/*/force_magnitude", "f8", ("T",), "N", finite=True, limit=FORCE_N),
        Dataset("presses/*/depth", "f8", ("T",), "m", limit=LAB_M,
                doc="tip below the rest plane along its normal (positive into the phantom); "
                    "a curved phantom's: below its touch point along touch_normal"),
        Dataset("presses/*/touch", "f8", (3,), "m", required=False, limit=LAB_M,
                doc="a curved phantom: where the tip touched the surface, lab"),
        Dataset("presses/*/touch_normal", "f8", (3,), "1", required=False,
                doc="a curved phantom: the surface's outward unit normal there, lab"),
        Dataset("presses/*/quality", "u1", ("T", "P"), doc="bitmask, see QUALITY_BITS"),
        Dataset("presses/*/force_quality", "u1", ("T",), doc="bitmask, see FORCE_BITS"),
    ),
)


def validate_synced(path: str | Path) -> None:
    """Check a synced file's layout and meaning; raise :class:`BadInput` naming the first fault.

    Layout and values (:data:`SYNCED`), then: at least one press; the rest-plane normal of unit
    length; per press, time strictly increasing, ``onset <= peak < release <= frames`` and the
    location one of ``locations/centre``, the depth that of its tip below the rest plane (so
    points, depth and plane share one unit).
    """
    validate_h5(path, SYNCED)
    with h5_reading(path), h5py.File(path, "r") as f:
        normal = f["calibration/surface_normal"][()]
        if abs(float(np.linalg.norm(normal)) - 1.0) > 1e-6:
            raise BadInput(path, f"calibration/surface_normal {normal} is not a unit vector")
        if not len(f["presses"]):
            raise BadInput(path, "the synced file holds no press")
        plane = (f["calibration/surface_point"][()], normal)
        points = len(f["point_names"])
        if points < MIN_MARKERS + 1:
            raise BadInput(path, f"point_names has {points} names: a phantom needs at least "
                                 f"{MIN_MARKERS} markers, then the tip")
        for key, press in f["presses"].items():
            if press["points"].shape[1] != points:
                raise BadInput(path, f"presses/{key}/points holds {press['points'].shape[1]} "
                                     f"points, but point_names names {points}")
            _check_press(path, f"presses/{key}", press, len(f["locations/centre"]))
            _check_depth(path, f"presses/{key}", press, _touch(path, key, press) if "touch"
                         in press else plane)


def _check_press(path: str | Path, name: str, press: h5py.Group, locations: int) -> None:
    """Increasing time, ordered onset/peak/release frames, a known location."""
    time = press["time_ns"][()]
    back = np.flatnonzero(np.diff(time) <= 0)
    if back.size:
        raise BadInput(path, f"{name}/time_ns does not increase at frame {back[0] + 1}")
    a = press.attrs
    onset, peak, release = (int(a[k]) for k in ("onset_index", "peak_index", "release_index"))
    if not 0 <= onset <= peak < release <= len(time):
        raise BadInput(path, f"{name}: onset {onset}, peak {peak}, release {release} are not "
                             f"ordered frames of its {len(time)}")
    if not 0 <= int(a["location"]) < locations:
        raise BadInput(path, f"{name}: location {a['location']} is not one of the "
                             f"{locations} in locations/centre")


def _touch(path: str | Path, key: str, press: h5py.Group) -> tuple[np.ndarray, np.ndarray]:
    """A curved phantom's press: where it touched and the unit normal there."""
    normal = press["touch_normal"][()]
    if abs(float(np.linalg.norm(normal)) - 1.0) > 1e-6:
        raise BadInput(path, f"presses/{key}/touch_normal {normal} is not a unit vector")
    return press["touch"][()], normal


def _check_depth(path: str | Path, name: str, press: h5py.Group,
                 plane: tuple[np.ndarray, np.ndarray]) -> None:
    """``depth`` is the tip's (the last point's) depth below the rest plane (a curved
    phantom's: the plane tangent where the press touched), to 1 um."""
    point, normal = plane
    expect = (point - press["points"][:, -1]) @ normal
    depth = press["depth"][()]
    off = np.flatnonzero(~np.isclose(depth, expect, rtol=0, atol=1e-6, equal_nan=True))
    if off.size:
        i = off[0]
        raise BadInput(path, f"{name}/depth at frame {i} is {depth[i]:.6g} m, but its tip lies "
                             f"{expect[i]:.6g} m below the rest plane: points, depth or plane "
                             "in another unit?")

"""The synced file (:data:`data_schema.synced.SYNCED`): a :class:`sync.sync.SyncResult` on disk.

Names, dtypes and units are the schema's; this module only says which array goes where.
"""

from __future__ import annotations

from pathlib import Path
from typing import Any

import numpy as np

from data_schema.hdf5 import write_h5
from data_schema.synced import FORCE_BITS, QUALITY_BITS, SYNCED
from sync.gaps import MISSING
from sync.presses import PressRecord
from sync.sync import SyncResult

GZIP = {"presses/*/points": 4, "presses/*/quality": 4}


def write_synced(path: str | Path, result: SyncResult, provenance: dict[str, Any],
                 source: str) -> None:
    """Write ``result`` to ``path`` (atomically, validated against the schema)."""
    arrays: dict[str, Any] = {
        "point_names": result.point_names,
        "calibration/cluster_body": result.cluster_body,
        "calibration/tip_body": result.pivot.tip_body,
        "calibration/force_bias": result.tare.bias,
        "calibration/surface_point": result.surface_point,
        "calibration/surface_normal": result.surface_normal,
        "locations/centre": result.location_centres.reshape(-1, 3),
    }
    if result.registration is not None:
        arrays.update({"calibration/to_shape": result.registration.to_shape,
                       "calibration/marker_residual": result.registration.residual})
    attrs: dict[str, Any] = {
        "provenance": provenance, "source": source, "calibration": result.calibration,
        "quality_bits": QUALITY_BITS, "force_bits": FORCE_BITS,
        "units_length": "m", "units_force": "N", "units_time": "ns",
        "rate_hz": result.rate_hz, "name": result.name, "phantom": result.phantom,
        "calibration/force_bias/units": ",".join(result.calibration["force"]["units"]),
        **{f"calibration/{k}": v for k, v in _calibration_attrs(result).items()},
        "presses/cut_off": result.presses_cut_off,
        "presses/in_holes": result.presses_in_holes, "holes": result.holes,
    }
    for k, rec in enumerate(result.presses):
        group = f"presses/{k:03d}"
        arrays.update({f"{group}/{name}": values for name, values in _press_arrays(rec).items()})
        attrs.update({f"{group}/{name}": value for name, value in _press_attrs(rec).items()})
    write_h5(path, SYNCED, arrays, attrs, gzip=GZIP)


def _calibration_attrs(result: SyncResult) -> dict[str, Any]:
    c = result.clock
    return {"clock_method": c.method, "clock_offset_s": c.offset_s,
            "clock_offset_sd_s": c.offset_sd_s, "clock_drift_ppm": c.drift_ppm,
            "clock_drift_sd_ppm": c.drift_sd_ppm, "clock_rms_s": c.rms_s, "clock_n": c.n,
            "tip_rms_m": result.pivot.rms,
            "tip_rotation_spread_deg": result.pivot.rotation_spread_deg}


def _press_arrays(rec: PressRecord) -> dict[str, np.ndarray]:
    out = {"time_ns": rec.time_ns, "points": rec.points, "force": rec.force,
           "torque": rec.torque, "force_magnitude": rec.force_magnitude, "depth": rec.depth,
           "quality": rec.quality, "force_quality": rec.force_quality}
    if rec.touch is not None:
        if rec.touch_normal is None:
            raise ValueError("a press's touch point without the surface's normal there")
        out.update(touch=rec.touch, touch_normal=rec.touch_normal)
    return out


def _press_attrs(rec: PressRecord) -> dict[str, Any]:
    pr = rec.press
    return {"location": pr.location, "repeat": pr.repeat, "onset_index": pr.onset,
            "peak_index": pr.peak, "release_index": pr.release,
            "onset_ns": int(rec.time_ns[pr.onset]),
            "release_ns": int(rec.time_ns[pr.release - 1]),
            "rest_force_n": rec.rest[:, :3], "rest_torque_nm": rec.rest[:, 3:],
            "points_missing_throughout": np.flatnonzero(
                (rec.quality[pr.onset:pr.release] & MISSING).all(axis=0)).astype(np.int64)}

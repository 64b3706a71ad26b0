"""How close a synced file is to the phantom twin's truth (for tests and the benchmark).

Compares ``pipeline sync``'s output (:mod:`data_schema.synced`) with the ``truth.h5`` of the
synthetic session it came from (:mod:`data_schema.truth`): the clock, the pivot-calibrated tip
offset, the tip and the force magnitude at the synced frames, and the presses found.
"""

from __future__ import annotations

from pathlib import Path

import numpy as np

from calib.rigid import fit_rigid
from data_schema.hdf5 import read_h5
from data_schema.synced import SYNCED
from data_schema.truth import TRUTH
from sync.sync_params import SyncParams

# What sync must reach on the twin, the demo's and the tests' targets (same keys as
# sync_errors' result).
TARGETS = {"clock_offset_ms": 0.5, "clock_drift_ppm": 5.0, "tip_rms_mm": 0.25,
           "tip_offset_mm": 0.2, "force_rms_n": 0.02}
# what the comparison needs of truth.h5 (the rest of it is large and not read)
TRUTH_READ = ("mocap/points", "force/magnitude", "indenter/markers", "indenter/tip",
              "clock/offset_s", "clock/drift_ppm", "presses/start_frame", "presses/end_frame",
              "presses/location")


def sync_errors(synced: str | Path, truth: str | Path) -> dict[str, float]:
    """Absolute errors of a synced file against the twin's truth.

    ``tip_rms_mm`` and ``force_rms_n`` are over every frame of every press record (margins
    included) where the value is present, ``tip_coverage`` the fraction of those frames that
    have a tip at all, and ``force_rms_loaded_n`` the force error from onset to release only;
    ``tip_offset_mm`` maps our body frame onto the twin's by the cluster shapes (an exact rigid
    fit) before comparing tip offsets. Presses are matched one to one by overlap (largest
    first): ``presses_missed`` counts true presses left without a synced press,
    ``presses_extra`` synced presses left without a true one, ``presses_merged`` synced presses
    that overlap more than one true press, and ``locations_mixed`` matched presses whose
    location id disagrees with the one-to-one mapping of the majority.
    """
    s, s_attrs = read_h5(synced, SYNCED)
    t, t_attrs = read_h5(truth, TRUTH, TRUTH_READ)
    rate = float(t_attrs["rate_hz"])
    true_points = t["mocap/points"][:, -1]
    true_force = t["force/magnitude"]
    tip_err, force_err, loaded_err, frames, ours = [], [], [], [], []
    for group in sorted({k.rsplit("/", 1)[0] for k in s if k.startswith("presses/")}):
        idx = np.round(s[f"{group}/time_ns"] * 1e-9 * rate).astype(np.int64)
        on, off = s_attrs[f"{group}/onset_index"], s_attrs[f"{group}/release_index"]
        tip_err.append(s[f"{group}/points"][:, -1] - true_points[idx])
        force_err.append(s[f"{group}/force_magnitude"] - true_force[idx])
        loaded_err.append(force_err[-1][on:off])
        frames.append((idx[on], idx[off - 1]))
        ours.append(int(s_attrs[f"{group}/location"]))
    tip = np.concatenate(tip_err)
    force = np.concatenate(force_err)
    to_truth = fit_rigid(s["calibration/cluster_body"], t["indenter/markers"][None],
                         SyncParams().max_fit_rms_m)
    tip_offset = to_truth.apply(s["calibration/tip_body"])[0] - t["indenter/tip"]
    match = match_presses(frames, ours, t["presses/start_frame"], t["presses/end_frame"],
                          t["presses/location"])
    cal = {k.split("/", 1)[1]: v for k, v in s_attrs.items() if k.startswith("calibration/")}
    return {
        "clock_offset_ms": float(abs(cal["clock_offset_s"] - t["clock/offset_s"])) * 1e3,
        "clock_drift_ppm": float(abs(cal["clock_drift_ppm"] - t["clock/drift_ppm"])),
        "clock_offset_sd_ms": float(cal["clock_offset_sd_s"]) * 1e3,
        "clock_drift_sd_ppm": float(cal["clock_drift_sd_ppm"]),
        "tip_rms_mm": _rms(tip) * 1e3,
        "tip_coverage": float(np.isfinite(tip).all(axis=1).mean()),
        "tip_offset_mm": float(np.linalg.norm(tip_offset)) * 1e3,
        "force_rms_n": _rms(force[:, None]),
        "force_rms_loaded_n": _rms(np.concatenate(loaded_err)[:, None]),
        "presses": float(len(ours)),
        **{k: float(v) for k, v in match.items()},
    }


def curved_errors(synced: str | Path, truth: str | Path) -> dict[str, float]:
    """A curved twin's registration and depth against its truth: each marker's residual off the
    registered shape (largest), the registered frame against the true one (the shape frame's
    points within the footprint moved by at most ``frame_mm``; its turn in degrees), and the
    depth along the normal from onset to release of every press (RMS and largest error; the
    true depth is the tip's below its true contact point along the true normal)."""
    s, s_attrs = read_h5(synced, SYNCED)
    t, t_attrs = read_h5(truth, TRUTH, ("mocap/depth", "phantom/shape_to_lab",
                                        "phantom/rest_surface"))
    rate = float(t_attrs["rate_hz"])
    ours = s["calibration/to_shape"] @ t["phantom/shape_to_lab"]      # true shape -> our shape
    nodes = t["phantom/rest_surface"].reshape(-1, 3)                 # lab
    back = np.linalg.inv(t["phantom/shape_to_lab"])
    surface = nodes @ back[:3, :3].T + back[:3, 3]                    # true shape frame
    moved = surface @ ours[:3, :3].T + ours[:3, 3]
    turn = np.degrees(np.arccos(np.clip((np.trace(ours[:3, :3]) - 1) / 2, -1.0, 1.0)))
    err = []
    for group in sorted({k.rsplit("/", 1)[0] for k in s if k.startswith("presses/")}):
        idx = np.round(s[f"{group}/time_ns"] * 1e-9 * rate).astype(np.int64)
        on, off = s_attrs[f"{group}/onset_index"], s_attrs[f"{group}/release_index"]
        err.append((s[f"{group}/depth"] - t["mocap/depth"][idx])[on:off])
    depth = np.concatenate(err)
    depth = depth[np.isfinite(depth)]
    return {"residual_max_mm": float(np.nanmax(np.abs(s["calibration/marker_residual"]))) * 1e3,
            "frame_mm": float(np.linalg.norm(moved - surface, axis=1).max()) * 1e3,
            "frame_deg": float(turn),
            "depth_rms_mm": float(np.sqrt(np.mean(depth ** 2))) * 1e3,
            "depth_max_mm": float(np.abs(depth).max()) * 1e3}


def _rms(err: np.ndarray) -> float:
    """RMS length of the rows of ``err`` that are finite (NaN when none is)."""
    ok = np.isfinite(err).all(axis=1)
    if not ok.any():
        return float("nan")
    return float(np.sqrt(np.mean(np.sum(err[ok] ** 2, axis=1))))


def match_presses(frames: list[tuple[int, int]], ours: list[int], start: np.ndarray,
                 end: np.ndarray, true_location: np.ndarray) -> dict[str, int]:
    """One-to-one matching of synced presses (first, last frame) to true ones by overlap."""
    a = np.array([f[0] for f in frames], np.int64).reshape(-1, 1)
    b = np.array([f[1] for f in frames], np.int64).reshape(-1, 1)
    overlap = np.clip(np.minimum(b, end[None]) - np.maximum(a, start[None]) + 1, 0, None)
    merged = int((((overlap > 0).sum(axis=1)) > 1).sum())
    pairs = []
    left = overlap.astype(float)
    while left.size and left.max() > 0:
        j, k = np.unravel_index(int(np.argmax(left)), left.shape)
        pairs.append((int(true_location[k]), ours[j]))
        left[j, :] = 0
        left[:, k] = 0
    mapping: dict[int, int] = {}
    for true_loc in {p[0] for p in pairs}:
        found = [o for t, o in pairs if t == true_loc]
        mapping[true_loc] = max(set(found), key=found.count)
    mixed = sum(1 for t, o in pairs if mapping[t] != o)
    if len(set(mapping.values())) < len(mapping):
        mixed += len(mapping) - len(set(mapping.values()))
    return {"presses_missed": len(start) - len(pairs), "presses_extra": len(ours) - len(pairs),
            "presses_merged": merged, "locations_mixed": mixed}

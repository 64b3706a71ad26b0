"""C3D exports (QTM, Vicon, ...) through ezc3d: 3D points, residuals, labels, rate and events.

ezc3d gives points as ``(4, N, T)`` in ``POINT:UNITS`` and residuals as ``(1, N, T)``; a negative
residual marks a missing sample. We return metres, NaN where missing, time 0 at the first frame.
"""

from __future__ import annotations

from pathlib import Path
from typing import Any

import numpy as np

from ingest.series import MarkerSeries
from pipeline.errors import BadInput

_LENGTH_UNITS = {"mm": 1e-3, "cm": 1e-2, "m": 1.0}


def _param(params: dict, group: str, name: str, path: str | Path) -> Any:
    try:
        return params[group][name]["value"]
    except KeyError:
        raise BadInput(path, f"C3D parameter {group}:{name} is missing") from None


def _labels(params: dict, n: int, path: str | Path) -> list[str]:
    """POINT:LABELS, continued in LABELS2, LABELS3 ... when there are more than 255 points."""
    labels = [str(s).strip() for s in _param(params, "POINT", "LABELS", path)]
    k = 2
    while len(labels) < n and f"LABELS{k}" in params["POINT"]:
        labels += [str(s).strip() for s in params["POINT"][f"LABELS{k}"]["value"]]
        k += 1
    labels = labels[:n]
    if len(labels) < n or any(not s for s in labels):
        raise BadInput(path, f"POINT:LABELS names {len(labels)} of {n} points")
    dups = sorted({s for s in labels if labels.count(s) > 1})
    if dups:
        raise BadInput(path, f"duplicate point label(s): {', '.join(dups)}")
    return labels


def _events(params: dict, start_s: float) -> list[tuple[str, int]]:
    """EVENT:LABELS at EVENT:TIMES ([minutes; seconds] from the trial start), on our clock."""
    ev = params.get("EVENT", {})
    if "LABELS" not in ev or "TIMES" not in ev:
        return []
    labels = [str(s).strip() for s in ev["LABELS"]["value"]]
    times = np.asarray(ev["TIMES"]["value"], dtype=np.float64).reshape(2, -1)
    seconds = times[0] * 60.0 + times[1] - start_s
    return [(lab, int(round(t * 1e9))) for lab, t in zip(labels, seconds, strict=False)]


def _header_frames(path: str | Path) -> int | None:
    """Frame count from the file's own header words (ezc3d rewrites its copy to what it read,
    so a truncated file would pass unnoticed); None when the header cannot say (> 65535)."""
    with open(path, "rb") as f:
        head = f.read(512)
        f.seek(max(0, (head[0] - 1) * 512))
        param = f.read(4)
    order = ">" if len(param) == 4 and param[3] == 86 else "<"            # 86: MIPS big-endian
    first, last = np.frombuffer(head[6:10], dtype=f"{order}u2")
    if last >= 65535 or last < first:
        return None
    return int(last) - int(first) + 1


def read_c3d(path: str | Path) -> MarkerSeries:
    """Read the 3D points of a C3D file: metres, NaN where the residual is negative."""
    import ezc3d

    if not Path(path).is_file():
        raise BadInput(path, "no such file")
    try:
        c = ezc3d.c3d(str(path))
    except Exception as e:  # ezc3d raises bare RuntimeError/IndexError/... on bad files
        raise BadInput(path, f"not a readable C3D file ({e})") from None
    params = c["parameters"]
    points = np.asarray(c["data"]["points"], dtype=np.float64)          # (4, N, T)
    residuals = np.asarray(c["data"]["meta_points"]["residuals"], dtype=np.float64)
    if points.ndim != 3 or points.shape[0] < 3:
        raise BadInput(path, f"C3D points have shape {points.shape}, expected (4, N, T)")
    n_points, n_frames = points.shape[1], points.shape[2]
    claimed = _header_frames(path)
    if claimed is not None and claimed != n_frames:
        raise BadInput(path, f"truncated: the header says {claimed} frames but {n_frames} "
                             "could be read", where=f"frame {n_frames}")
    rate = float(np.ravel(_param(params, "POINT", "RATE", path))[0])
    if not (np.isfinite(rate) and rate > 0):
        raise BadInput(path, f"POINT:RATE {rate:g} is not a positive rate")
    units = str(np.ravel(_param(params, "POINT", "UNITS", path))[0]).strip()
    if units not in _LENGTH_UNITS:
        raise BadInput(path, f"POINT:UNITS {units!r} is not a length unit (mm, cm, m)")
    scale = _LENGTH_UNITS[units]
    labels = _labels(params, n_points, path)

    positions = points[:3].transpose(2, 1, 0) * scale                   # (T, N, 3)
    res = residuals.reshape(n_points, n_frames).T * scale               # (T, N)
    missing = (res < 0) | np.isnan(res) | np.isnan(positions).any(axis=2)
    positions[missing] = np.nan
    res[missing] = np.nan
    first_frame = int(c["header"]["points"]["first_frame"])             # 0-based in ezc3d
    time_ns = np.rint(np.arange(n_frames, dtype=np.float64) * 1e9 / rate).astype(np.int64)
    meta = {
        "format": "c3d", "units_in_file": units, "first_frame": first_frame,
        "analog_rate": float(c["header"]["analogs"]["frame_rate"]),
    }
    return MarkerSeries(source=str(path), time_ns=time_ns, labels=labels, positions=positions,
                        rate_hz=rate, residuals=res, events=_events(params, first_frame / rate),
                        meta=meta)

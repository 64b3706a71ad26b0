"""Holes cut into a twin session's lab files, as a DAQ overrun or a dropped QTM stream leaves
them: the rows of the lost samples are gone, every other row is as recorded.

Cut by hand from the files' own layout (a QTM TSV's data rows, whose ``NO_OF_FRAMES`` then
says how many rows are left, as QTM writes it for a capture with lost frames; the force CSV's
rows), independent of the pipeline's readers.
"""

from __future__ import annotations

from pathlib import Path

import h5py
import numpy as np


def press_spans_s(truth: Path) -> np.ndarray:
    """Each true press's (start, end) on the mocap clock (s), from ``truth.h5``."""
    with h5py.File(truth) as t:
        times = t["mocap/time_s"][()]
        start, end = t["presses/start_frame"][()], t["presses/end_frame"][()]
    return np.stack([times[start], times[np.minimum(end, len(times) - 1)]], axis=1)


def to_logger_s(truth: Path, t_mocap_s: float) -> float:
    """A mocap time (s) on the force logger's clock (the twin's true clock model)."""
    with h5py.File(truth) as t:
        offset, drift = float(t["clock/offset_s"][()]), float(t["clock/drift_ppm"][()])
    return offset + (1 + drift * 1e-6) * t_mocap_s


COUNT_KEYS = ("NO_OF_FRAMES", "NO_OF_SAMPLES", "CHANNEL_SAMPLE_COUNTS")


def cut_qtm_tsv(path: Path, start_s: float, length_s: float) -> int:
    """Remove the data rows of a QTM TSV export (3D, 6D, analog or force plate: a ``Frame
    Time`` or ``SAMPLE TIME`` column line) whose time lies in [start, start + length); the
    header's counts say how many rows are left. Returns the rows removed."""
    text = path.read_bytes().decode()
    newline = "\r\n" if "\r\n" in text else "\n"
    lines = text.split(newline)
    header = next(i for i, line in enumerate(lines) if line.startswith(("Frame\t", "SAMPLE\t")))
    kept, removed = lines[:header + 1], 0
    for line in lines[header + 1:]:
        if line and start_s <= float(line.split("\t", 2)[1]) < start_s + length_s:
            removed += 1
        else:
            kept.append(line)
    rows = sum(1 for line in kept[header + 1:] if line)
    for i, line in enumerate(kept[:header]):
        key, _, values = line.partition("\t")
        if key in COUNT_KEYS:
            kept[i] = key + "\t" + "\t".join(str(rows) for _ in values.split("\t"))
    path.write_bytes(newline.join(kept).encode())
    return removed


def cut_mocap(session: Path, start_s: float, length_s: float) -> int:
    """Lost mocap frames in [start, start + length) s of the capture: cut from the 3D export
    and the 6D export of the same capture. Returns the frames lost."""
    removed = cut_qtm_tsv(session / "indentation.tsv", start_s, length_s)
    six = session / "indentation_6D.tsv"
    if six.exists():
        assert cut_qtm_tsv(six, start_s, length_s) == removed
    return removed


def cut_force(session: Path, start_s: float, length_s: float) -> int:
    """Lost force samples in [start, start + length) s of the logger's clock, cut from
    ``force.csv``. Returns the samples lost."""
    path = session / "force.csv"
    lines = path.read_text().splitlines(keepends=True)
    kept, removed = lines[:1], 0
    for line in lines[1:]:
        t = float(line.split(",", 1)[0])
        if start_s <= t < start_s + length_s:
            removed += 1
        else:
            kept.append(line)
    path.write_text("".join(kept))
    return removed

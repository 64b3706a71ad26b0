"""QTM TSV exports for the tests of ``ingest/qtm_*.py``: the real samples, small files written
line by line, and the check that a file is refused with its path and the right words."""

from __future__ import annotations

from pathlib import Path

import pytest

from core.errors import BadInput
from helpers.paths import REAL_SAMPLES
from ingest.qtm_motion import read_qtm_tsv

QTM = REAL_SAMPLES / "qtm"
OLD_3D = QTM / "qtm2010_3d_noheader_nan_gaps.tsv"
NEW_3D = QTM / "qtm2026_3d_15markers_100hz.tsv"
OLD_6D = QTM / "qtm2010_6d_3bodies.tsv"


def raw_rows(path: Path, skip: int) -> list[list[str]]:
    """The data rows of a real file, split by hand (an independent reading)."""
    lines = path.read_text().splitlines()[skip:]
    return [line.split("\t") for line in lines if line.strip()]


def qtm_header(names: list[str], frames: int, rate: float = 500, key: str = "MARKER_NAMES",
               extra: tuple[str, ...] = ()) -> list[str]:
    """The header lines of a 3D (``MARKER_NAMES``) or 6D (``BODY_NAMES``) export."""
    count = "NO_OF_MARKERS" if key == "MARKER_NAMES" else "NO_OF_BODIES"
    return [f"NO_OF_FRAMES\t{frames}", "NO_OF_CAMERAS\t8", f"{count}\t{len(names)}",
            f"FREQUENCY\t{rate:g}", "NO_OF_ANALOG\t0", "ANALOG_FREQUENCY\t0", "DESCRIPTION\t--",
            "TIME_STAMP\t2026-11-21, 09:12:00",
            "DATA_INCLUDED\t" + ("3D" if key == "MARKER_NAMES" else "6D"), *extra,
            key + "\t" + "\t".join(names)]


def write_tsv(tmp_path: Path, lines: list[str], name: str = "t.tsv", end: str = "\r\n") -> Path:
    """``lines`` written as a file, each ended by ``end`` (QTM writes CRLF)."""
    p = tmp_path / name
    p.write_bytes((end.join(lines) + end).encode())
    return p


def good_3d_lines(frames: int = 4, claimed: int | None = None) -> list[str]:
    """A valid 3D export of markers A and B with a column line (NO_OF_FRAMES may lie)."""
    cols = "Frame\tTime\tA X\tA Y\tA Z\tB X\tB Y\tB Z"
    rows = [f"{i + 1}\t{i * 0.002:.5f}\t{i}.125\t2.250\t3.375\t4.500\t5.625\t6.750"
            for i in range(frames)]
    return [*qtm_header(["A", "B"], frames if claimed is None else claimed), cols, *rows]


def refused(path: Path, *needles: str) -> BadInput:
    """The BadInput ``read_qtm_tsv`` refuses ``path`` with; it names the file and ``needles``."""
    with pytest.raises(BadInput) as e:
        read_qtm_tsv(path)
    msg = str(e.value)
    assert str(path) in msg
    for n in needles:
        assert n in msg
    return e.value

"""Headers that contradict the data are refused with one line naming the file and the key: no
marker's data is dropped or shifted without a word (QTM TSV 3D and 6D, QTM MAT)."""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pytest
import scipy.io
from click.testing import CliRunner

from core.errors import BadInput
from ingest.qtm_mat import read_qtm_mat, write_mat73
from ingest.qtm_tsv import read_qtm_tsv
from pipeline.cli import cli

pytestmark = pytest.mark.usefixtures("real_samples")


def _variant(real_samples: Path, tmp_path: Path, name: str, edit) -> Path:
    lines = (real_samples / "qtm" / name).read_text().split("\n")
    out = tmp_path / f"edited_{name}"
    out.write_text("\n".join(edit(lines)))
    return out


def _replace(i: int, text: str):
    return lambda lines: lines[:i] + [text] + lines[i + 1:]


QTM2026 = "qtm2026_3d_15markers_100hz.tsv"      # header keys, Frame/Time column line
QTM2010 = "qtm2010_3d_noheader_nan_gaps.tsv"    # no column line
QTM6D = "qtm2010_6d_3bodies.tsv"

CASES = [
    (QTM2026, _replace(3, "FREQUENCY\tabc"), "line 4: FREQUENCY 'abc' is not a number"),
    (QTM2026, _replace(0, "NO_OF_FRAMES\t2k"), "NO_OF_FRAMES '2k' is not a number"),
    (QTM2026, _replace(1, "NO_OF_CAMERAS\tmany"), "NO_OF_CAMERAS 'many' is not a number"),
    (QTM2026, _replace(4, "NO_OF_ANALOG\tnone"), "NO_OF_ANALOG 'none' is not a number"),
    (QTM2026, _replace(2, "NO_OF_MARKERS\t14"), "NO_OF_MARKERS is 14 but MARKER_NAMES lists 15"),
    # the column line names a marker MARKER_NAMES does not list (and misses one it does)
    (QTM2026, lambda L: L[:11] + [L[11].replace("New 0002 X\tNew 0002 Y\tNew 0002 Z",
                                                "Foo X\tFoo Y\tFoo Z")] + L[12:],
     "column line names marker(s) ['Foo']"),
    # MARKER_NAMES lists one marker fewer than the column line and the data hold
    (QTM2026, lambda L: L[:2] + ["NO_OF_MARKERS\t14"] + L[3:9]
     + ["\t".join(L[9].split("\t")[:-1]), "\t".join(L[10].split("\t")[:-1])] + L[11:],
     "column line names marker(s) ['New 0015'] that MARKER_NAMES does not list (14 names)"),
    (QTM2026, lambda L: L[:12] + [x + "\t1.0\t2.0\t3.0" if x else x for x in L[12:]],
     "row has 50 fields but the column line names 47"),
    (QTM2010, lambda L: L[:2] + ["NO_OF_MARKERS\t13"] + L[3:9]
     + ["\t".join(L[9].split("\t")[:-1])] + L[10:], "13 markers need 39"),
    (QTM2010, lambda L: L[:10] + [x + "\t1\t2\t3" if x else x for x in L[10:]],
     "row has 45 fields; 14 markers need 42"),
    (QTM6D, _replace(2, "NO_OF_BODIES\t4"), "NO_OF_BODIES is 4 but BODY_NAMES lists 3"),
    (QTM6D, _replace(2, "NO_OF_BODIES\tthree"), "NO_OF_BODIES 'three' is not a number"),
    (QTM6D, lambda L: L[:2] + ["NO_OF_BODIES\t2"] + L[3:9]
     + ["BODY_NAMES\tUpper Leg IMU\tFoot IMU"] + L[10:], "does not fit 2 bodies"),
]


@pytest.mark.parametrize(("name", "edit", "message"), CASES)
def test_a_contradicting_header_is_refused(real_samples, tmp_path, name, edit, message):
    path = _variant(real_samples, tmp_path, name, edit)
    with pytest.raises(BadInput) as err:
        read_qtm_tsv(path)
    assert message in err.value.line() and str(path) in err.value.line()


def test_the_real_exports_still_read(real_samples):
    for name in (QTM2026, QTM2010, QTM6D):
        read_qtm_tsv(real_samples / "qtm" / name)


def test_cli_says_one_line_and_writes_nothing(real_samples, tmp_path):
    bad = _variant(real_samples, tmp_path, QTM2026, _replace(3, "FREQUENCY\tabc"))
    res = CliRunner().invoke(cli, ["inspect", str(bad)])
    assert res.exit_code == 2
    assert res.stderr.strip().splitlines() == [f"error: {bad}:line 4: FREQUENCY 'abc' is not "
                                               "a number"]


def _mat_struct(count: float) -> dict:
    """A QTM MAT struct of two markers over four frames whose Count field says ``count``."""
    data = np.zeros((2, 4, 4))
    return {"File": "t.mat", "StartFrame": 1.0, "Frames": 4.0, "FrameRate": 100.0,
            "Timestamp": "", "Trajectories": {"Labeled": {"Count": count,
                                                          "Labels": ["A", "B"], "Data": data}}}


@pytest.mark.parametrize("version", ["7", "7.3"])
def test_mat_count_that_contradicts_the_data(tmp_path, version):
    for count, ok in ((2.0, True), (3.0, False)):
        path = tmp_path / f"t{version}_{count:.0f}.mat"
        struct = _mat_struct(count)
        if version == "7.3":
            write_mat73(path, {"t": struct})
        else:
            labels = np.empty((1, 2), dtype=object)
            labels[0, :] = ["A", "B"]
            struct["Trajectories"]["Labeled"]["Labels"] = labels
            scipy.io.savemat(path, {"t": struct}, oned_as="row")
        if ok:
            assert read_qtm_mat(path).labels == ["A", "B"]
        else:
            with pytest.raises(BadInput, match="Labeled.Count is 3 but Data holds 2"):
                read_qtm_mat(path)

"""Format detection by content (a wrong extension does not fool it) and read_mocap dispatch."""

from __future__ import annotations

import json
from pathlib import Path

import h5py
import numpy as np
import pandas as pd
import pytest
import scipy.io
from helpers.paths import REAL_SAMPLES
from mcap.writer import Writer

from core.errors import BadInput
from ingest.ati_cal import read_ati_cal, write_ati_cal
from ingest.detect import detect_format, read_mocap
from ingest.qtm_3d import read_qtm_3d
from ingest.qtm_mat import write_mat73, write_qtm_mat
from ingest.sniff import sniff

pytestmark = pytest.mark.usefixtures("real_samples")

REAL = REAL_SAMPLES


@pytest.mark.parametrize(("path", "fmt"), [
    ("qtm/qtm2010_3d_noheader_nan_gaps.tsv", "qtm_tsv_3d"),
    ("qtm/qtm2026_3d_15markers_100hz.tsv", "qtm_tsv_3d"),
    ("qtm/qtm2010_6d_3bodies.tsv", "qtm_tsv_6d"),
    ("c3d/qualisys_55markers_200hz.c3d", "c3d"),
    ("ati/nano17_FT14048_SI-50-0.5.cal", "ati_cal"),
])
def test_real_samples(path, fmt):
    assert detect_format(REAL / path) == fmt


def _make(tmp: Path) -> dict[str, Path]:
    """One file of every other format, each under a misleading extension."""
    df = pd.DataFrame({"time": [0.0, 0.001, 0.002], "G0": [0.1, 0.2, 0.3]})
    files = {name: tmp / f"{name}.dat" for name in (
        "force_csv", "force_tsv", "force_parquet", "force_mat", "force_mat73", "qtm_mat",
        "qtm_mat73", "ati_cal", "mcap", "hdf5", "json")}
    df.to_csv(files["force_csv"], index=False)
    df.to_csv(files["force_tsv"], index=False, sep="\t")
    df.to_parquet(files["force_parquet"])
    scipy.io.savemat(files["force_mat"], {c: df[c].to_numpy() for c in df})
    write_mat73(files["force_mat73"], {c: df[c].to_numpy() for c in df})
    series = read_qtm_3d(REAL / "qtm" / "qtm2026_3d_15markers_100hz.tsv")
    write_qtm_mat(files["qtm_mat"], series, version="7")
    write_qtm_mat(files["qtm_mat73"], series, version="7.3")
    write_ati_cal(files["ati_cal"], read_ati_cal(REAL / "ati" / "nano17_FT14048_SI-50-0.5.cal"))
    with open(files["mcap"], "wb") as f:
        w = Writer(f)
        w.start()
        w.finish()
    with h5py.File(files["hdf5"], "w") as f:
        f["x"] = np.arange(3)
    files["json"].write_text(json.dumps([{"train": [0], "val": [1]}]))
    return files


def test_generated_files_of_every_format(tmp_path):
    files = _make(tmp_path)
    expected = {"force_csv": "force_csv", "force_tsv": "force_csv",
                "force_parquet": "force_parquet", "force_mat": "force_mat",
                "force_mat73": "force_mat", "qtm_mat": "qtm_mat", "qtm_mat73": "qtm_mat",
                "ati_cal": "ati_cal", "mcap": "mcap", "hdf5": "hdf5", "json": "json"}
    assert {k: detect_format(p) for k, p in files.items()} == expected
    assert sniff(files["qtm_mat73"]) == "mat73" and sniff(files["hdf5"]) == "hdf5"


def test_mat_header_text_may_vary(tmp_path):
    """Only the version and endian bytes (124-127) make a MAT file; writers vary the text."""
    p = tmp_path / "log.mat"
    scipy.io.savemat(p, {"time": np.arange(3.0), "G0": np.zeros(3)})
    with open(p, "r+b") as f:
        f.write(b"phantom twin force log".ljust(116))
    assert sniff(p) == "mat5" and detect_format(p) == "force_mat"


@pytest.mark.parametrize("content", [
    b"", b"\x00\xff\x10binary junk" * 40, b"Dear colleague,\nplease find the data.\n",
    b"<svg xmlns='http://www.w3.org/2000/svg'/>", b"1,2,3\n4,5,6\n",
])
def test_unknown_formats(tmp_path, content):
    p = tmp_path / "x.tsv"
    p.write_bytes(content)
    with pytest.raises(BadInput, match="unknown format") as e:
        detect_format(p)
    assert str(p) in str(e.value)


def test_missing_file(tmp_path):
    with pytest.raises(BadInput, match="no such file"):
        detect_format(tmp_path / "nope.tsv")


def test_read_mocap_dispatch(tmp_path):
    tsv = read_mocap(REAL / "qtm" / "qtm2026_3d_15markers_100hz.tsv")
    c3d = read_mocap(REAL / "c3d" / "qualisys_55markers_200hz.c3d")
    assert (tsv.frames, c3d.frames) == (2000, 340)
    files = _make(tmp_path)
    for key in ("qtm_mat", "qtm_mat73"):
        m = read_mocap(files[key])
        assert m.labels == tsv.labels
        assert np.allclose(m.positions, tsv.positions, equal_nan=True, atol=1e-12)
    for path in (REAL / "qtm" / "qtm2010_6d_3bodies.tsv", files["force_csv"]):
        with pytest.raises(BadInput, match="not a 3D marker export"):
            read_mocap(path)


def _qtm_mat(tmp: Path, compress: bool = True) -> Path:
    from ingest.qtm_mat import _struct_name, write_qtm_mat

    path = tmp / "trial.mat"
    series = read_qtm_3d(REAL / "qtm" / "qtm2026_3d_15markers_100hz.tsv")
    write_qtm_mat(path, series, version="7")
    if not compress:                                      # the same struct, uncompressed
        struct = scipy.io.loadmat(path, squeeze_me=False)[_struct_name(path)]
        scipy.io.savemat(path, {"trial": struct}, do_compression=False)
    return path


def test_mat_struct_names_are_sniffed_without_inflating_the_data(tmp_path):
    """Detection reads only variable headers: a QTM export damaged in the middle of its
    compressed data is still a QTM export, and reading it is bad input naming the struct."""
    path = _qtm_mat(tmp_path)
    raw = bytearray(path.read_bytes())
    raw[len(raw) // 2:len(raw) // 2 + 64] = bytes(64)
    path.write_bytes(bytes(raw))
    assert detect_format(path) == "qtm_mat"
    with pytest.raises(BadInput, match="cannot read the QTM struct 'trial'"):
        read_mocap(path)


def test_uncompressed_qtm_mat_and_force_mat_with_a_struct(tmp_path):
    assert detect_format(_qtm_mat(tmp_path, compress=False)) == "qtm_mat"
    assert read_mocap(tmp_path / "trial.mat").frames == 2000
    log = tmp_path / "log.mat"
    scipy.io.savemat(log, {"time": np.arange(3.0), "G0": np.zeros(3),
                           "meta": {"sensor": "FT14048", "rate": 1000.0}})
    assert detect_format(log) == "force_mat"


@pytest.mark.parametrize("version", ["7", "7.3"])
def test_truncated_mat_is_unreadable_not_a_force_log(tmp_path, version):
    from ingest.qtm_mat import write_qtm_mat

    path = tmp_path / "trial.mat"
    write_qtm_mat(path, read_qtm_3d(REAL / "qtm" / "qtm2026_3d_15markers_100hz.tsv"), version)
    path.write_bytes(path.read_bytes()[: path.stat().st_size // 2])
    with pytest.raises(BadInput, match="cannot read MAT file") as e:
        detect_format(path)
    assert str(path) in str(e.value)


def test_read_mocap_names_a_6d_export():
    with pytest.raises(BadInput, match="is a QTM 6D .* not a 3D marker export"):
        read_mocap(REAL / "qtm" / "qtm2010_6d_3bodies.tsv")

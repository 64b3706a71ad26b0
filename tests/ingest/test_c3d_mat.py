"""C3D (ezc3d) and QTM MAT (v7 / v7.3) readers: the real C3D export, C3D files with missing
samples, MAT files built by hand the way QTM and MATLAB lay them out, and bad input."""

from __future__ import annotations

from pathlib import Path

import ezc3d
import h5py
import numpy as np
import pytest
import scipy.io
from helpers.paths import REAL_SAMPLES
from scipy.io.matlab import matfile_version

from core.errors import BadInput
from core.series import MarkerSeries
from ingest.c3d import read_c3d
from ingest.qtm_mat import read_qtm_mat, write_mat73, write_qtm_mat

pytestmark = pytest.mark.usefixtures("real_samples")

C3D = REAL_SAMPLES / "c3d" / \
    "qualisys_55markers_200hz.c3d"


# ---------------------------------------------------------------------------- C3D


def test_real_c3d_export():
    s = read_c3d(C3D)
    raw = ezc3d.c3d(str(C3D))
    assert s.frames == 340 and s.rate_hz == 200.0 and len(s.labels) == 55
    assert s.labels[:5] == ["L_IAS", "L_IPS", "R_IPS", "R_IAS", "SNJ"]
    points = raw["data"]["points"]
    assert s.positions[0, 0] == pytest.approx(points[:3, 0, 0] / 1000)      # mm -> m
    assert s.positions[123, 40] == pytest.approx(points[:3, 40, 123] / 1000)
    residuals = raw["data"]["meta_points"]["residuals"]
    assert s.missing_samples() == int((residuals < 0).sum()) == 0
    assert s.time_ns[-1] == round(339 / 200 * 1e9)
    # events: EVENT:TIMES seconds, minus the first frame's time (raw header frame 705)
    assert s.events[0][0] == "LHS"
    assert s.events[0][1] == pytest.approx((3.59 - 704 / 200) * 1e9, abs=1e3)


def _c3d(path: Path, points_mm: np.ndarray, residuals: np.ndarray, units: str = "mm",
         labels: list[str] | None = None) -> Path:
    c = ezc3d.c3d()
    n = points_mm.shape[1]
    c["parameters"]["POINT"]["RATE"]["value"] = [500]
    c["parameters"]["POINT"]["LABELS"]["value"] = labels or [f"P{i}" for i in range(n)]
    c["parameters"]["POINT"]["UNITS"]["value"] = [units]
    pts = np.ones((4, *points_mm.shape[1:]))
    pts[:3] = points_mm
    c["data"]["points"] = pts
    c["data"]["meta_points"] = {"residuals": residuals,
                                "camera_masks": np.zeros((7, *residuals.shape[1:]), bool)}
    c.write(str(path))
    return path


def test_c3d_missing_samples_match_raw_residuals(tmp_path):
    rng = np.random.default_rng(3)
    pts = rng.normal(0, 100, (3, 6, 50))
    res = np.full((1, 6, 50), 1.0)
    res[0, rng.integers(0, 6, 17), rng.integers(0, 50, 17)] = -1.0
    s = read_c3d(_c3d(tmp_path / "gaps.c3d", pts, res))
    raw = ezc3d.c3d(str(tmp_path / "gaps.c3d"))["data"]["meta_points"]["residuals"]
    assert s.missing_samples() == int((raw < 0).sum()) == int((res < 0).sum())
    ok = res[0].T >= 0
    assert np.isnan(s.positions[~ok]).all()
    assert s.positions[ok] == pytest.approx(pts.transpose(2, 1, 0)[ok] / 1000, rel=1e-6)
    assert s.rate_hz == 500 and s.time_ns[1] == 2_000_000


def test_c3d_units_in_metres(tmp_path):
    pts = np.arange(3 * 2 * 4, dtype=float).reshape(3, 2, 4)
    s = read_c3d(_c3d(tmp_path / "m.c3d", pts, np.zeros((1, 2, 4)), units="m"))
    assert s.positions[3, 1] == pytest.approx(pts[:, 1, 3])


def test_c3d_bad_input(tmp_path):
    cut = tmp_path / "cut.c3d"
    cut.write_bytes(C3D.read_bytes()[:600_000])
    with pytest.raises(BadInput, match="truncated") as e:
        read_c3d(cut)
    assert str(cut) in str(e.value)
    junk = tmp_path / "junk.c3d"
    junk.write_bytes(C3D.read_bytes()[:3000])
    with pytest.raises(BadInput, match="junk.c3d"):
        read_c3d(junk)
    feet = _c3d(tmp_path / "ft.c3d", np.zeros((3, 1, 2)), np.zeros((1, 1, 2)), units="ft")
    with pytest.raises(BadInput, match="POINT:UNITS 'ft'"):
        read_c3d(feet)


@pytest.mark.parametrize("size", [512, 520, 600, 5780, 14000])
def test_c3d_cut_before_its_data_is_refused_before_ezc3d_reads_it(tmp_path, size):
    """ezc3d segfaulted (520 bytes) or hung (5780) on these: the header's sizes are checked
    first (parameter section from byte 512, 27 blocks; data from block 29)."""
    cut = tmp_path / "cut.c3d"
    cut.write_bytes(C3D.read_bytes()[:size])
    with pytest.raises(BadInput, match="truncated: .* before the parameter section|truncated: "
                                       ".* inside the parameter section"):
        read_c3d(cut)


@pytest.mark.parametrize("offset, value", [(5571, 184), (5730, 243), (11518, 136)])
def test_c3d_damaged_parameter_record_is_refused(tmp_path, offset, value):
    """One byte of a record's link to the next (or of a description length) changed: ezc3d
    crashed or looped on these; the parameter walk refuses them."""
    data = bytearray(C3D.read_bytes())
    data[offset] = value
    bad = tmp_path / "bad.c3d"
    bad.write_bytes(bytes(data))
    with pytest.raises(BadInput, match="damaged parameter section") as e:
        read_c3d(bad)
    assert e.value.where.startswith("byte ")


def test_c3d_files_ezc3d_writes_pass_the_parameter_walk(tmp_path):
    pts = np.zeros((3, 300, 2))                       # 300 points: LABELS and LABELS2
    s = read_c3d(_c3d(tmp_path / "many.c3d", pts, np.zeros((1, 300, 2)),
                      labels=[f"M{i}" for i in range(300)]))
    assert len(s.labels) == 300 and s.labels[299] == "M299"


# ---------------------------------------------------------------------------- QTM MAT


def _known(m: int = 3, t: int = 40) -> tuple[np.ndarray, list[str]]:
    """QTM's Data (M x 4 x T, mm, residual last) with two gaps, and labels with spaces."""
    rng = np.random.default_rng(7)
    data = np.empty((m, 4, t))
    data[:, :3] = rng.normal(0, 200, (m, 3, t))
    data[:, 3] = rng.uniform(0.1, 0.9, (m, t))
    data[1, :, 5] = np.nan
    data[m - 1, :, t - 10] = np.nan
    return data, [f"Marker {i} - tip" for i in range(m)]


def _check(s: MarkerSeries, data: np.ndarray, labels: list[str], rate: float) -> None:
    assert s.labels == labels and s.rate_hz == rate and s.frames == data.shape[2]
    assert s.missing_samples() == 2
    assert np.allclose(s.positions, data[:, :3].transpose(2, 0, 1) / 1000, equal_nan=True)
    assert np.allclose(s.residuals, data[:, 3].T / 1000, equal_nan=True)
    assert s.time_ns[1] == round(1e9 / rate)


def test_qtm_mat_v7_as_qtm_writes_it(tmp_path):
    data, labels = _known()
    cell = np.empty((1, len(labels)), dtype=object)
    cell[0, :] = labels
    qtm = {"File": "C:\\data\\Measurement1.qtm", "Timestamp": "2026-11-21, 09:12:00.125",
           "StartFrame": 1.0, "Frames": 40.0, "FrameRate": 500.0,
           "Trajectories": {"Labeled": {"Count": 3.0, "Labels": cell, "Data": data}}}
    p = tmp_path / "Measurement1.mat"
    scipy.io.savemat(p, {"Measurement1": qtm})
    s = read_qtm_mat(p)
    _check(s, data, labels, 500.0)
    assert s.meta["struct"] == "Measurement1"
    assert s.meta["timestamp"] == "2026-11-21, 09:12:00.125"


def _h5_char(group: h5py.Group, name: str, text: str) -> h5py.Dataset:
    ds = group.create_dataset(name, data=np.array([[ord(c)] for c in text], np.uint16))
    ds.attrs["MATLAB_class"] = np.bytes_("char")
    ds.attrs["MATLAB_int_decode"] = np.int32(2)
    return ds


def test_qtm_mat_v73_laid_out_as_matlab_does(tmp_path):
    """Built by hand: MATLAB userblock, MATLAB_class attributes, reversed dimensions, cellstr
    as object references to uint16 char arrays."""
    data, labels = _known(m=2, t=25)
    p = tmp_path / "trial.mat"
    with h5py.File(p, "w", userblock_size=512) as f:
        refs = f.create_group("#refs#")
        s = f.create_group("trial_7")
        s.attrs["MATLAB_class"] = np.bytes_("struct")
        for key, value in (("Frames", 25.0), ("FrameRate", 250.0), ("StartFrame", 3.0)):
            s.create_dataset(key, data=np.array([[value]])).attrs["MATLAB_class"] = b"double"
        _h5_char(s, "Timestamp", "2026-11-21, 09:12:00")
        lab = s.create_group("Trajectories").create_group("Labeled")
        cells = np.array([[_h5_char(refs, f"c{i}", t).ref] for i, t in enumerate(labels)],
                         dtype=h5py.ref_dtype)
        lab.create_dataset("Labels", data=cells).attrs["MATLAB_class"] = b"cell"
        lab.create_dataset("Data", data=data.transpose(2, 1, 0)).attrs["MATLAB_class"] = \
            b"double"
    with open(p, "r+b") as fh:
        fh.write(b"MATLAB 7.3 MAT-file, Platform: GLNXA64, Created on: test HDF5 schema 1.00 ."
                 .ljust(116) + bytes(8) + b"\x00\x02IM")
    s = read_qtm_mat(p)
    _check(s, data, labels, 250.0)
    assert s.meta["start_frame"] == 3 and s.meta["timestamp"] == "2026-11-21, 09:12:00"


@pytest.mark.parametrize("version", ["7", "7.3"])
def test_write_qtm_mat_round_trip(tmp_path, version):
    data, labels = _known()
    s = MarkerSeries(source="x", time_ns=np.arange(40) * 2_000_000, labels=labels,
                     positions=data[:, :3].transpose(2, 0, 1) / 1000, rate_hz=500.0,
                     residuals=data[:, 3].T / 1000, meta={"timestamp": "2026-11-21"})
    s.positions[np.isnan(s.residuals)] = np.nan
    p = tmp_path / f"out-{version}.mat"
    write_qtm_mat(p, s, version=version)
    assert matfile_version(p) == ((1, 0) if version == "7" else (2, 0))
    back = read_qtm_mat(p)
    _check(back, data, labels, 500.0)
    assert back.meta["timestamp"] == "2026-11-21"
    if version == "7.3":
        with h5py.File(p) as f:
            lab = f["out_7_3/Trajectories/Labeled"]
            assert lab["Data"].shape == (40, 4, 3)                    # MATLAB order reversed
            assert f["out_7_3"].attrs["MATLAB_class"] == b"struct"
            first = f[lab["Labels"][0, 0]]
            assert first.dtype == np.uint16 and first.attrs["MATLAB_class"] == b"char"


def test_qtm_mat_bad_input(tmp_path):
    data, labels = _known()
    cell = np.empty((1, 3), dtype=object)
    cell[0, :] = labels
    good = {"Frames": 40.0, "FrameRate": 500.0,
            "Trajectories": {"Labeled": {"Labels": cell, "Data": data}}}
    cases = {
        "frames.mat": ({"M": {**good, "Frames": 41.0}}, "Frames is 41 but Data has 40"),
        "labels.mat": ({"M": {**good, "Trajectories": {"Labeled": {"Labels": cell[:, :2],
                                                                   "Data": data}}}},
                       "2 labels for 3 trajectories"),
        "force.mat": ({"time": np.arange(5.0), "Fx": np.zeros(5)}, "no QTM struct"),
        "two.mat": ({"A": good, "B": good}, "several QTM structs"),
    }
    cases["rate.mat"] = ({"M": {**good, "FrameRate": 0.0}}, "M.FrameRate 0 is not a frame rate")
    for name, (content, message) in cases.items():
        scipy.io.savemat(tmp_path / name, content)
        with pytest.raises(BadInput, match=message) as e:
            read_qtm_mat(tmp_path / name)
        assert name in str(e.value)
    write_mat73(tmp_path / "cut.mat", {"M": {**good, "Trajectories": {
        "Labeled": {"Labels": labels, "Data": data}}}})
    raw = (tmp_path / "cut.mat").read_bytes()
    (tmp_path / "cut.mat").write_bytes(raw[: len(raw) // 2])
    with pytest.raises(BadInput, match="cut.mat"):
        read_qtm_mat(tmp_path / "cut.mat")


def test_qtm_mat_v7_damaged_compressed_data(tmp_path):
    data, labels = _known(m=3, t=4000)
    s = MarkerSeries(source="x", time_ns=np.arange(4000) * 2_000_000, labels=labels,
                     positions=data[:, :3].transpose(2, 0, 1) / 1000, rate_hz=500.0)
    p = tmp_path / "trial.mat"
    write_qtm_mat(p, s, version="7")
    raw = bytearray(p.read_bytes())
    raw[len(raw) // 2:len(raw) // 2 + 64] = bytes(64)
    p.write_bytes(bytes(raw))
    with pytest.raises(BadInput, match="trial.mat: cannot read the QTM struct 'trial'"):
        read_qtm_mat(p)

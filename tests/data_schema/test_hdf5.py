"""The schema-driven HDF5 writer and reader (data_schema.hdf5.write_h5 / read_h5)."""

from __future__ import annotations

import json

import h5py
import numpy as np
import pytest

from core.errors import BadInput
from data_schema.hdf5 import Dataset, H5Schema, read_h5, write_h5

LAYOUT = H5Schema(
    name="test.layout", version="1.2", root_attrs=("provenance", "rate_hz"),
    group_attrs={"runs/*": ("label",)},
    datasets=(
        Dataset("names", "str", ("N",)),
        Dataset("runs/*/time", "i8", ("T",), "ns"),
        Dataset("runs/*/points", "f8", ("T", "N", 3), "m"),
        Dataset("runs/*/flags", "u1", ("T",)),
    ),
)


def _arrays(frames: tuple[int, ...] = (5, 7000)) -> dict[str, object]:
    out: dict[str, object] = {"names": ["a", "b"]}
    for k, t in enumerate(frames):
        out[f"runs/{k:03d}/time"] = np.arange(t) * 2_000_000        # int, stored as i8
        out[f"runs/{k:03d}/points"] = np.full((t, 2, 3), 0.5, np.float32)
        out[f"runs/{k:03d}/flags"] = np.zeros(t, int)
    return out


def _attrs() -> dict[str, object]:
    return {"provenance": {"stage": "test", "params": {"x": 1}}, "rate_hz": 500.0,
            "runs/000/label": "first", "runs/001/label": "second",
            "runs/001/flags/units": "bits"}


def test_layout_gives_dtype_units_and_schema(tmp_path):
    path = tmp_path / "f.h5"
    write_h5(path, LAYOUT, _arrays(), _attrs(), gzip={"runs/*/points": 4})
    with h5py.File(path) as f:
        assert f.attrs["schema"] == "test.layout" and f.attrs["schema_version"] == "1.2"
        assert json.loads(f.attrs["provenance"]) == {"stage": "test", "params": {"x": 1}}
        assert f["runs/000/time"].dtype == np.int64 and f["runs/000/time"].attrs["units"] == "ns"
        assert f["runs/001/points"].dtype == np.float64
        assert f["runs/001/points"].attrs["units"] == "m"
        flags = f["runs/001/flags"]
        assert flags.dtype == np.uint8 and flags.attrs["units"] == "bits"
        assert "units" not in f["runs/000/flags"].attrs
        # compression only where asked and only for datasets worth it (5 x 6 values are not)
        assert f["runs/001/points"].compression == "gzip"
        assert f["runs/000/points"].compression is None and f["runs/001/time"].compression is None


def test_read_gives_back_what_was_written(tmp_path):
    path = tmp_path / "f.h5"
    arrays = _arrays()
    write_h5(path, LAYOUT, arrays, _attrs())
    got, attrs = read_h5(path, LAYOUT)
    assert set(got) == set(arrays)
    assert list(got["names"]) == ["a", "b"]
    for key in arrays:
        if key != "names":
            assert np.array_equal(got[key], np.asarray(arrays[key]))
    assert attrs["runs/001/label"] == "second" and attrs["rate_hz"] == 500.0
    assert attrs["runs/000/time/units"] == "ns" and attrs["schema"] == "test.layout"
    only, _ = read_h5(path, LAYOUT, datasets=["runs/*/time"])
    assert sorted(only) == ["runs/000/time", "runs/001/time"]


def test_a_file_that_breaks_its_layout_is_never_written(tmp_path):
    path = tmp_path / "f.h5"
    arrays = _arrays()
    arrays["runs/001/flags"] = np.zeros(3, int)             # T disagrees within the run
    with pytest.raises(BadInput, match="T="):
        write_h5(path, LAYOUT, arrays, _attrs())
    attrs = _attrs()
    del attrs["rate_hz"]                                     # a required root attribute
    with pytest.raises(BadInput, match="rate_hz"):
        write_h5(path, LAYOUT, _arrays(), attrs)
    assert list(tmp_path.iterdir()) == []


def test_undeclared_dataset_and_units_against_the_layout_are_refused(tmp_path):
    with pytest.raises(ValueError, match="not a dataset"):
        write_h5(tmp_path / "f.h5", LAYOUT, {**_arrays(), "extra": np.zeros(2)}, _attrs())
    with pytest.raises(ValueError, match="units come from the schema"):
        write_h5(tmp_path / "f.h5", LAYOUT, _arrays(), {**_attrs(), "runs/000/time/units": "s"})
    assert list(tmp_path.iterdir()) == []


def test_read_validates_first(tmp_path):
    path = tmp_path / "f.h5"
    write_h5(path, LAYOUT, _arrays(), _attrs())
    with h5py.File(path, "a") as f:
        f["runs/000/time"].attrs["units"] = "s"
    with pytest.raises(BadInput, match="units"):
        read_h5(path, LAYOUT)

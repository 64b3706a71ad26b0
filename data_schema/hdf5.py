"""Declarative HDF5 layouts and their validator.

A layout lists the root attributes a file must carry and its datasets, each with dtype, a
symbolic shape (names bind to sizes, so ``("S", "N", 3)`` in two datasets must agree) and units.
A ``*`` path segment matches every member of a group (one per press, say); names in a shape
bind separately within each such member.
"""

from __future__ import annotations

from dataclasses import dataclass, field
from pathlib import Path

import h5py
import numpy as np

from core.atomic import atomic_output
from core.errors import BadInput

Dim = int | str


@dataclass(frozen=True)
class Dataset:
    """One dataset of a layout."""

    path: str                  # e.g. "states/points" or "presses/*/time_ns"
    dtype: str                 # numpy kind+size: "f8", "f4", "i8", "i4", "u1", "b1", or "str"
    shape: tuple[Dim, ...]     # ints are exact, strings are named sizes
    units: str | None = None   # the ``units`` attribute the dataset must carry
    required: bool = True
    doc: str = ""


@dataclass(frozen=True)
class H5Schema:
    """A versioned HDF5 file layout."""

    name: str                                  # root attribute ``schema``
    version: str                               # root attribute ``schema_version``
    datasets: tuple[Dataset, ...]
    root_attrs: tuple[str, ...] = ("provenance",)
    doc: str = ""
    group_attrs: dict[str, tuple[str, ...]] = field(default_factory=dict)


def read_schema_id(path: str | Path) -> tuple[str, str] | None:
    """The (schema, version) an HDF5 file declares, or None when it declares none."""
    try:
        with h5py.File(path, "r") as f:
            name, version = f.attrs.get("schema"), f.attrs.get("schema_version")
    except OSError as e:
        raise BadInput(path, f"not a readable HDF5 file ({e})") from None
    if name is None or version is None:
        return None
    return _text(name), _text(version)


def validate_h5(path: str | Path, schema: H5Schema) -> None:
    """Raise :class:`BadInput` naming the first way ``path`` departs from ``schema``."""
    try:
        f = h5py.File(path, "r")
    except OSError as e:
        raise BadInput(path, f"not a readable HDF5 file ({e})") from None
    with f:
        _check_root(path, f, schema)
        for grp, attrs in schema.group_attrs.items():
            for member in _expand(f, grp):
                missing = [a for a in attrs if a not in f[member].attrs]
                if missing:
                    raise BadInput(path, f"group {member} lacks attribute(s) {missing}")
        bound: dict[str, dict[str, int]] = {}
        for ds in schema.datasets:
            _check_dataset(path, f, ds, bound)


def _check_root(path: str | Path, f: h5py.File, schema: H5Schema) -> None:
    name, version = _text(f.attrs.get("schema", "")), _text(f.attrs.get("schema_version", ""))
    if name != schema.name:
        raise BadInput(path, f"schema is {name!r}, expected {schema.name!r}")
    if version.split(".")[0] != schema.version.split(".")[0]:
        raise BadInput(path, f"schema version {version} is not compatible with {schema.version}")
    missing = [a for a in schema.root_attrs if a not in f.attrs]
    if missing:
        raise BadInput(path, f"missing root attribute(s) {missing}")


def _check_dataset(
    path: str | Path, f: h5py.File, ds: Dataset, bound: dict[str, dict[str, int]]
) -> None:
    members = _expand(f, ds.path)
    if not members and ds.required and "*" not in ds.path:
        raise BadInput(path, f"missing dataset {ds.path}")
    for member in members:
        obj = f[member]
        if not isinstance(obj, h5py.Dataset):
            raise BadInput(path, f"{member} is not a dataset")
        _check_dtype(path, member, obj, ds.dtype)
        scope = _scope(ds.path, member)
        _check_shape(path, member, obj.shape, ds.shape, bound.setdefault(scope, {}))
        if ds.units is not None and _text(obj.attrs.get("units", "")) != ds.units:
            raise BadInput(path, f"{member} units are {obj.attrs.get('units')!r}, "
                                 f"expected {ds.units!r}")


def _expand(f: h5py.File, pattern: str) -> list[str]:
    """Concrete paths matching a pattern whose segments may be ``*``."""
    paths = [""]
    for seg in pattern.split("/"):
        nxt = []
        for p in paths:
            grp = f[p] if p else f
            if not isinstance(grp, h5py.Group):
                continue
            names = sorted(grp.keys()) if seg == "*" else ([seg] if seg in grp else [])
            nxt += [f"{p}/{n}" if p else n for n in names]
        paths = nxt
    return paths


def _scope(pattern: str, member: str) -> str:
    """Named sizes bind per file, or per member of the last ``*`` group in the pattern."""
    segs = pattern.split("/")
    if "*" not in segs:
        return ""
    last = len(segs) - 1 - segs[::-1].index("*")
    return "/".join(member.split("/")[: last + 1])


def _check_dtype(path: str | Path, member: str, obj: h5py.Dataset, want: str) -> None:
    if want == "str":
        ok = h5py.check_string_dtype(obj.dtype) is not None
    else:
        ok = np.dtype(obj.dtype) == np.dtype(want)
    if not ok:
        raise BadInput(path, f"{member} has dtype {obj.dtype}, expected {want}")


def _check_shape(path: str | Path, member: str, got: tuple[int, ...],
                 want: tuple[Dim, ...], bound: dict[str, int]) -> None:
    if len(got) != len(want):
        raise BadInput(path, f"{member} has shape {got}, expected {want}")
    for size, dim in zip(got, want, strict=True):
        if isinstance(dim, int):
            if size != dim:
                raise BadInput(path, f"{member} has shape {got}, expected {want}")
        elif bound.setdefault(dim, size) != size:
            raise BadInput(path, f"{member} has {dim}={size}, but another dataset has "
                                 f"{dim}={bound[dim]}")


def _text(v: object) -> str:
    return v.decode() if isinstance(v, bytes) else str(v)


def attr_text(v: object) -> str:
    """An HDF5 string attribute as text (h5py gives ``bytes`` or ``str``)."""
    return _text(v)


def write_h5(path: str | Path, schema: H5Schema, arrays: dict[str, np.ndarray],
             attrs: dict[str, object]) -> None:
    """Write ``arrays`` (dataset path -> array) and root ``attrs`` as a file of ``schema``.

    Each array is cast to its schema dtype and given its schema units; a name the schema does
    not declare is a programming error. The file is validated before it is renamed into place,
    so a file of the final name always matches its schema.
    """
    declared = {d.path: d for d in schema.datasets}
    unknown = sorted(set(arrays) - set(declared))
    if unknown:
        raise ValueError(f"{schema.name} declares no dataset(s) {unknown}")
    with atomic_output(path) as tmp:
        with h5py.File(tmp, "w") as f:
            f.attrs["schema"], f.attrs["schema_version"] = schema.name, schema.version
            for key, value in attrs.items():
                f.attrs[key] = value
            for name, data in arrays.items():
                ds_schema = declared[name]
                dtype = h5py.string_dtype() if ds_schema.dtype == "str" else ds_schema.dtype
                ds = f.create_dataset(name, data=np.asarray(data).astype(dtype))
                if ds_schema.units is not None:
                    ds.attrs["units"] = ds_schema.units
        validate_h5(tmp, schema)


def read_datasets(path: str | Path, names: list[str] | None = None) -> dict[str, np.ndarray]:
    """Every dataset of a file (or the ``names`` given) as arrays, keyed by path."""
    with h5py.File(path, "r") as f:
        if names is None:
            names = []
            f.visititems(lambda n, o: names.append(n) if isinstance(o, h5py.Dataset) else None)
        return {n: f[n][()] for n in sorted(names) if n in f}

"""Declarative HDF5 layouts, their validator, and the one writer and reader of such files.

A layout lists the root attributes a file must carry and its datasets, each with dtype, a
symbolic shape (names bind to sizes, so ``("S", "N", 3)`` in two datasets must agree) and units.
A ``*`` path segment matches every member of a group (one per press, say); names in a shape
bind separately within each such member.

:func:`write_h5` takes the arrays and attributes of a file and its layout, and takes from the
layout what the layout already says (schema name and version, each dataset's dtype and units),
so a writer restates nothing; it validates the file before it is renamed into place.
:func:`read_h5` validates a file, then hands back its arrays and attributes. Attributes of
groups and datasets are named by path, ``"<object path>/<attribute>"`` (``"presses/000/location"``);
a name without ``/`` is a root attribute.
"""

from __future__ import annotations

import contextlib
from collections.abc import Iterable, Iterator, Mapping
from dataclasses import dataclass, field
from fnmatch import fnmatchcase
from pathlib import Path
from typing import Any

import h5py
import numpy as np

from core.atomic import atomic_output
from core.errors import BadInput
from core.text import attr_text, to_json

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
    finite: bool | str = False  # True: no NaN/inf; a path: finite where that bool dataset is
    limit: float | None = None  # largest plausible |value| in ``units`` (catches mm, mN)


@dataclass(frozen=True)
class H5Schema:
    """A versioned HDF5 file layout."""

    name: str                                  # root attribute ``schema``
    version: str                               # root attribute ``schema_version``
    datasets: tuple[Dataset, ...]
    root_attrs: tuple[str, ...] = ("provenance",)
    doc: str = ""
    group_attrs: dict[str, tuple[str, ...]] = field(default_factory=dict)
    fixed_attrs: dict[str, str] = field(default_factory=dict)   # root attribute -> its value


# A scaled value's likely unit, for the message that refuses it.
SCALED_UNIT = {"m": "millimetres", "N": "millinewtons", "m/s": "mm/s", "N*m": "mN*m"}
READ_ERRORS: tuple[type[Exception], ...] = (OSError, KeyError, ValueError, TypeError,
                                            RuntimeError, IndexError)


@contextlib.contextmanager
def h5_reading(path: str | Path) -> Iterator[None]:
    """Turn a failure inside h5py (a damaged, truncated or odd file) into :class:`BadInput`."""
    try:
        yield
    except BadInput:
        raise
    except READ_ERRORS as e:
        raise BadInput(path, f"not a readable HDF5 file ({type(e).__name__}: {e})") from None


def read_schema_id(path: str | Path) -> tuple[str, str] | None:
    """The (schema, version) an HDF5 file declares, or None when it declares none."""
    with h5_reading(path), h5py.File(path, "r") as f:
        name, version = f.attrs.get("schema"), f.attrs.get("schema_version")
    if name is None or version is None:
        return None
    return attr_text(name), attr_text(version)


def validate_h5(path: str | Path, schema: H5Schema) -> None:
    """Raise :class:`BadInput` naming the first way ``path`` departs from ``schema``.

    Layout (attributes, datasets, dtypes, shapes, units), then values: finite where the layout
    says so, and no larger than a dataset's plausible ``limit``.
    """
    with h5_reading(path), h5py.File(path, "r") as f:
        _check_root(path, f, schema)
        for grp, attrs in schema.group_attrs.items():
            for member in _expand(f, grp):
                missing = [a for a in attrs if a not in f[member].attrs]
                if missing:
                    raise BadInput(path, f"group {member} lacks attribute(s) {missing}")
        bound: dict[str, dict[str, int]] = {}
        for ds in schema.datasets:
            _check_dataset(path, f, ds, bound)
        for ds in schema.datasets:
            if ds.finite or ds.limit is not None:
                for member in _expand(f, ds.path):
                    _check_values(path, f, member, ds)


def _check_root(path: str | Path, f: h5py.File, schema: H5Schema) -> None:
    name = attr_text(f.attrs.get("schema", ""))
    version = attr_text(f.attrs.get("schema_version", ""))
    if name != schema.name:
        raise BadInput(path, f"schema is {name!r}, expected {schema.name!r}")
    if version.split(".")[0] != schema.version.split(".")[0]:
        raise BadInput(path, f"schema version {version} is not compatible with {schema.version}")
    missing = [a for a in schema.root_attrs if a not in f.attrs]
    if missing:
        raise BadInput(path, f"missing root attribute(s) {missing}")
    for attr, want in schema.fixed_attrs.items():
        got = attr_text(f.attrs.get(attr, ""))
        if got != want:
            raise BadInput(path, f"root attribute {attr} is {got!r}, expected {want!r}")


def _check_dataset(
    path: str | Path, f: h5py.File, ds: Dataset, bound: dict[str, dict[str, int]]
) -> None:
    members = _expand(f, ds.path)
    if not members and ds.required and "*" not in ds.path:
        raise BadInput(path, f"missing dataset {ds.path}")
    if ds.required and "*" in ds.path:
        absent = _absent_members(f, ds.path)
        if absent:
            raise BadInput(path, f"missing dataset {absent[0]}")
    for member in members:
        obj = f[member]
        if not isinstance(obj, h5py.Dataset):
            raise BadInput(path, f"{member} is not a dataset")
        _check_dtype(path, member, obj, ds.dtype)
        scope = _scope(ds.path, member)
        _check_shape(path, member, obj.shape, ds.shape, bound.setdefault(scope, {}))
        if ds.units is not None and attr_text(obj.attrs.get("units", "")) != ds.units:
            raise BadInput(path, f"{member} units are {obj.attrs.get('units')!r}, "
                                 f"expected {ds.units!r}")


def _check_values(path: str | Path, f: h5py.File, member: str, ds: Dataset) -> None:
    """Finite where required; no inf and nothing beyond the plausible limit (a scaled unit)."""
    values = f[member][()]
    if ds.finite:
        need = np.True_
        if isinstance(ds.finite, str):
            need = f[ds.finite][()]
            need = need.reshape(need.shape + (1,) * (values.ndim - need.ndim))
        where = f" where {ds.finite} is True" if isinstance(ds.finite, str) else ""
        _refuse_first(path, ~np.isfinite(values) & need, f"{member} is not finite at index "
                      "{at} ({value})" + where, values)
    if ds.limit is not None:
        _refuse_first(path, np.isinf(values), f"{member} is infinite at index {{at}}", values)
        big = np.abs(np.where(np.isfinite(values), values, 0.0))
        _refuse_first(path, big > ds.limit, f"{member} reaches {{value:.4g}} {ds.units} at "
                      f"index {{at}}, more than a plausible {ds.limit:g} {ds.units}: "
                      f"{SCALED_UNIT.get(ds.units or '', 'another unit')}? It is stored in "
                      f"{ds.units}", big)


def _refuse_first(path: str | Path, bad: np.ndarray, message: str, values: np.ndarray) -> None:
    """Raise :class:`BadInput` with ``message`` (``{at}``, ``{value}``) at the first bad index."""
    hits = np.argwhere(bad)
    if hits.size:
        at = tuple(int(i) for i in hits[0])
        raise BadInput(path, message.format(at=at, value=values[at]))


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


def _absent_members(f: h5py.File, pattern: str) -> list[str]:
    """Where each member of the pattern's last ``*`` group lacks the rest of the pattern."""
    segs = pattern.split("/")
    last = len(segs) - 1 - segs[::-1].index("*")
    rest = "/".join(segs[last + 1:])
    return [f"{g}/{rest}" for g in _expand(f, "/".join(segs[: last + 1]))
            if isinstance(f[g], h5py.Group) and rest not in f[g]]


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



# --- writing and reading ----------------------------------------------------------------------

GZIP_MIN_ITEMS = 4096     # smaller datasets stay uncompressed: the filter would cost more


def write_h5(path: str | Path, schema: H5Schema, arrays: Mapping[str, Any],
             attrs: Mapping[str, Any], *, gzip: Mapping[str, int] | None = None,
             track_order: bool = False) -> None:
    """Write ``arrays`` (dataset path -> values) and ``attrs`` to ``path`` in ``schema``'s layout.

    Each dataset is stored with the dtype and ``units`` its :class:`Dataset` entry declares (a
    path no entry matches is a programming error); ``attrs`` are named as in the module
    docstring, dicts and lists are stored as JSON text, and ``schema``/``schema_version`` come
    from ``schema``. ``gzip`` maps dataset patterns of the layout to a gzip level (applied to
    numeric datasets of more than :data:`GZIP_MIN_ITEMS` values); ``track_order`` keeps the
    creation order of members. Written atomically and validated before it takes the name.
    """
    entries = [(name, _entry(schema, name), values) for name, values in arrays.items()]
    with atomic_output(path) as tmp:
        with h5py.File(tmp, "w", track_order=track_order) as f:
            f.attrs.update({"schema": schema.name, "schema_version": schema.version})
            for name, entry, values in entries:
                _create(f, name, entry, values, (gzip or {}).get(entry.path))
            for key, value in attrs.items():
                owner, _, attr = key.rpartition("/")
                obj = f if not owner else f[owner] if owner in f else f.require_group(owner)
                if attr == "units" and isinstance(obj, h5py.Dataset) and "units" in obj.attrs:
                    raise ValueError(f"write_h5: {owner} units come from the schema")
                obj.attrs[attr] = _attr_value(value)
        validate_h5(tmp, schema)


def read_h5(path: str | Path, schema: H5Schema, datasets: Iterable[str] | None = None
            ) -> tuple[dict[str, np.ndarray], dict[str, Any]]:
    """Validate ``path`` against ``schema``, then read it: (arrays, attrs).

    ``arrays`` maps each dataset path present (``*`` expanded) to its values, text datasets as
    arrays of ``str``; ``datasets`` limits them to these layout patterns. ``attrs`` holds the
    attributes of the root, every group and every dataset read, named as in the module
    docstring, text as ``str``.
    """
    validate_h5(path, schema)
    wanted = [d.path for d in schema.datasets] if datasets is None else list(datasets)
    with h5_reading(path), h5py.File(path, "r") as f:
        arrays = {m: _values(f[m]) for pattern in wanted for m in _expand(f, pattern)}
        attrs: dict[str, Any] = {}
        groups = [""]
        f.visititems(lambda name, obj: groups.append(name)
                     if isinstance(obj, h5py.Group) else None)
        for owner in [*groups, *arrays]:
            obj = f[owner] if owner else f
            attrs.update({f"{owner}/{k}" if owner else k: _attr_read(v)
                          for k, v in obj.attrs.items()})
    return arrays, attrs


def _entry(schema: H5Schema, name: str) -> Dataset:
    """The layout entry a concrete dataset path falls under."""
    segs = name.split("/")
    for ds in schema.datasets:
        pattern = ds.path.split("/")
        if len(pattern) == len(segs) and all(fnmatchcase(s, p) for s, p in
                                             zip(segs, pattern, strict=True)):
            return ds
    raise ValueError(f"write_h5: {name} is not a dataset of {schema.name}")


def _create(f: h5py.File, name: str, entry: Dataset, values: Any, level: int | None) -> None:
    if entry.dtype == "str":
        data = np.array([str(v) for v in np.ravel(values)], dtype=object).reshape(np.shape(values))
        ds = f.create_dataset(name, data=data, dtype=h5py.string_dtype())
    else:
        data = np.asarray(values, dtype=entry.dtype)
        packed = level is not None and data.size > GZIP_MIN_ITEMS
        kw = {"compression": "gzip", "compression_opts": level, "shuffle": True} if packed \
            else {}
        ds = f.create_dataset(name, data=data, **kw)
    if entry.units is not None:
        ds.attrs["units"] = entry.units


def _attr_value(value: Any) -> Any:
    """Dicts and lists as JSON text; numbers, text and arrays as they are."""
    return to_json(value) if isinstance(value, dict | list) else value


def _values(ds: h5py.Dataset) -> np.ndarray:
    if h5py.check_string_dtype(ds.dtype) is not None:
        return np.asarray(ds.asstr()[()], dtype=object)
    return ds[()]


def _attr_read(value: Any) -> Any:
    return attr_text(value) if isinstance(value, bytes | str) else value

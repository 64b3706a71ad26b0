"""QTM MAT exports: one top-level struct (named after the measurement) holding
``Trajectories.Labeled.Data`` (M x 4 x T: X, Y, Z in mm and the residual), ``.Labels``,
``FrameRate``, ``Frames`` and optionally ``StartFrame`` and ``Timestamp``.

MAT v7 files are read with scipy.io; v7.3 files are HDF5 with a MATLAB userblock, read with h5py
(MATLAB stores arrays with their dimensions reversed, and cell arrays of strings as object
references to uint16 character arrays). ``write_qtm_mat`` writes both, for tests and the twin.
Telling a QTM export from a force log reads only each variable's header (``mat5_structs``), so
a compressed export is inflated once, by the read itself.
"""

from __future__ import annotations

import re
import struct
import zlib
from pathlib import Path
from typing import Any

import h5py
import numpy as np
import scipy.io

from core.atomic import atomic_output
from core.errors import BadInput
from core.series import MarkerSeries, frame_times_ns
from ingest.sniff import sniff

_SKIP = ("#refs#", "#subsystem#")
# What scipy.io, h5py and the MAT header walk raise on a damaged file; every MAT reader
# turns these into BadInput.
MAT_ERRORS: tuple[type[Exception], ...] = (OSError, ValueError, TypeError, KeyError, IndexError,
                                           EOFError, NotImplementedError, zlib.error,
                                           struct.error, RuntimeError,
                                           scipy.io.matlab.MatReadError)
_MI_COMPRESSED, _MX_STRUCT = 15, 2
_HEAD_BYTES = 1 << 16          # of a variable, enough for its header and struct field names


# ---------------------------------------------------------------------------- reading


def is_qtm_mat(path: str | Path) -> bool:
    """Whether a MAT file (v7 or v7.3) holds a QTM export struct (one with ``Trajectories``).

    Reads only the first bytes of each variable (its header and field names), never the data;
    a file that cannot be read that far is bad input, not "some other MAT file".
    """
    return bool(_struct_names(path))


def _struct_names(path: str | Path) -> list[str]:
    """Names of the top-level structs with a ``Trajectories`` field."""
    kind = sniff(path)
    if kind not in ("mat5", "mat73"):
        raise BadInput(path, f"not a MAT file (found {kind})")
    try:
        if kind == "mat73":
            with h5py.File(path, "r") as f:
                return [k for k in f if k not in _SKIP and isinstance(f[k], h5py.Group)
                        and "Trajectories" in f[k]]
        return [name for name, fields in mat5_structs(path).items() if "Trajectories" in fields]
    except MAT_ERRORS as e:
        raise BadInput(path, f"cannot read MAT file ({e})") from None


def mat5_structs(path: str | Path) -> dict[str, list[str]]:
    """The top-level struct variables of a MAT v5/v7 file with their field names.

    Walks the variable tags (MAT-File Format, "Data Element"), reading the first bytes of each
    variable only: a compressed one is inflated just past its field names, so sniffing a large
    QTM export costs microseconds, not a decompression. Damage -> the errors of MAT_ERRORS.
    """
    out: dict[str, list[str]] = {}
    with open(path, "rb") as f:
        head = f.read(128)
        order = "<" if head[126:128] == b"IM" else ">"
        size = Path(path).stat().st_size
        while tag := f.read(8):
            dtype, nbytes = struct.unpack(order + "II", tag)
            start = f.tell()
            if start + nbytes > size:
                raise EOFError(f"variable at byte {start - 8} runs past the end of the file "
                               "(truncated)")
            if dtype == _MI_COMPRESSED:
                z = zlib.decompressobj()
                body = z.decompress(f.read(min(nbytes, _HEAD_BYTES)), _HEAD_BYTES)
            else:
                body = tag + f.read(min(nbytes, _HEAD_BYTES))
            name, fields = _matrix_head(body, order)
            if fields is not None:
                out[name] = fields
            f.seek(start + nbytes)
    return out


def _matrix_head(buf: bytes, order: str) -> tuple[str, list[str] | None]:
    """Name and, for a struct, field names of one miMATRIX element (its first bytes)."""
    def element(pos: int) -> tuple[bytes, int]:
        kind, n = struct.unpack_from(order + "II", buf, pos)
        if kind >> 16:                   # small element: size in the upper half, data inline
            return buf[pos + 4:pos + 4 + (kind >> 16)], pos + 8
        return buf[pos + 8:pos + 8 + n], pos + 8 + n + (-n % 8)

    flags, pos = element(8)              # skip the miMATRIX tag itself
    mclass = struct.unpack_from(order + "I", flags)[0] & 0xFF
    _dims, pos = element(pos)
    name, pos = element(pos)
    if mclass != _MX_STRUCT:
        return name.decode("latin-1"), None
    length, pos = element(pos)
    width = struct.unpack_from(order + "i", length)[0]
    names, _ = element(pos)
    fields = [names[i:i + width].split(b"\0", 1)[0].decode("latin-1")
              for i in range(0, len(names), width)] if width > 0 else []
    return name.decode("latin-1"), fields


def read_qtm_mat(path: str | Path) -> MarkerSeries:
    """Read the labeled trajectories of a QTM MAT export (v7 or v7.3) in metres."""
    names = _struct_names(path)
    if len(names) != 1:
        raise BadInput(path, "no QTM struct with Trajectories in this MAT file" if not names
                       else f"several QTM structs in this MAT file: {', '.join(names)}")
    name = names[0]
    try:
        fields = _read73(path, name) if sniff(path) == "mat73" else _read7(path, name)
    except MAT_ERRORS as e:
        raise BadInput(path, f"cannot read the QTM struct {name!r} ({e})") from None
    return _series(path, name, fields)


def _series(path: str | Path, name: str, f: dict[str, Any]) -> MarkerSeries:
    data, labels = f["data"], f["labels"]
    if data.ndim == 2:                      # MATLAB drops a trailing singleton: one frame
        data = data[:, :, None]
    if data.ndim != 3 or data.shape[1] not in (3, 4):
        raise BadInput(path, f"{name}.Trajectories.Labeled.Data has shape {data.shape}, "
                             "expected markers x 4 x frames")
    m, _, t = data.shape
    if len(labels) != m:
        raise BadInput(path, f"{name}.Trajectories.Labeled.Labels: {len(labels)} labels for "
                             f"{m} trajectories in Data")
    count = _number(path, f"{name}.Trajectories.Labeled.Count", f["count"], whole=True)
    if count is not None and count != m:
        raise BadInput(path, f"{name}.Trajectories.Labeled.Count is {count} but Data holds "
                             f"{m} trajectories")
    dups = sorted({s for s in labels if labels.count(s) > 1})
    if dups or any(not s for s in labels):
        raise BadInput(path, f"empty or duplicate label(s) in {name}: {', '.join(dups)}")
    frames = _number(path, f"{name}.Frames", f["frames"], whole=True)
    if frames is not None and frames != t:
        raise BadInput(path, f"{name}.Frames is {frames} but Data has {t} frames")
    rate = _number(path, f"{name}.FrameRate", f["rate"])
    if rate is None:
        raise BadInput(path, f"{name}.FrameRate is missing: the frames cannot be timed")
    start = _number(path, f"{name}.StartFrame", f["start_frame"], whole=True)
    time_ns = frame_times_ns(t, rate, path, f"{name}.FrameRate")
    positions = data[:, :3, :].transpose(2, 0, 1) * 1e-3                # (T, M, 3) metres
    res = data[:, 3, :].T * 1e-3 if data.shape[1] == 4 else np.zeros((t, m))
    missing = np.isnan(positions).any(axis=2) | np.isnan(res) | (res < 0)
    positions[missing] = np.nan
    res[missing] = np.nan
    meta = {"format": "qtm_mat", "struct": name, "units_in_file": "mm",
            "start_frame": start, "timestamp": f["timestamp"] or None}
    return MarkerSeries(source=str(path), time_ns=time_ns, labels=labels, positions=positions,
                        rate_hz=float(rate), residuals=res, meta=meta)


def _number(path: str | Path, what: str, value: Any, whole: bool = False) -> Any:
    """A numeric field of the QTM struct (one finite number; a count when ``whole``), or None
    when the struct has no such field; anything else is bad input naming the field."""
    if value is None:
        return None
    arr = np.asarray(value)
    if arr.dtype.kind not in "iuf" or arr.size != 1:
        shown = repr(str(arr.ravel()[0])) if arr.dtype.kind in "US" and arr.size else \
            f"a {arr.dtype.kind} array of shape {arr.shape}"
        raise BadInput(path, f"{what} is not a number ({shown})")
    v = float(arr.ravel()[0])
    if not np.isfinite(v) or (whole and not (v.is_integer() and v >= 0)):
        raise BadInput(path, f"{what} {v:g} is not a {'count' if whole else 'finite number'}")
    return int(v) if whole else v


def _read7(path: str | Path, name: str) -> dict[str, Any]:
    s = scipy.io.loadmat(path, variable_names=[name], squeeze_me=False)[name]

    def field(struct: np.ndarray, key: str, required: bool = True) -> Any:
        """The value of ``struct.key`` (a 1x1 struct array as scipy gives it)."""
        if struct.size != 1 or key not in (struct.dtype.names or ()):
            if required:
                raise KeyError(f"no field {key} in a 1x1 struct")
            return None
        return struct[key].flat[0]

    labeled = field(field(s, "Trajectories"), "Labeled")
    labels = [str(np.ravel(x)[0]).strip() if np.size(x) else "" for x in
              np.ravel(field(labeled, "Labels"))]
    stamp = field(s, "Timestamp", False)
    return {
        "data": np.asarray(field(labeled, "Data"), dtype=np.float64),
        "labels": labels,
        "count": field(labeled, "Count", False),
        "rate": field(s, "FrameRate", False),
        "frames": field(s, "Frames", False),
        "start_frame": field(s, "StartFrame", False),
        "timestamp": None if stamp is None or not np.size(stamp) else str(np.ravel(stamp)[0]),
    }


def mat73_text(ds: h5py.Dataset) -> str:
    """A MATLAB char array stored in HDF5 (uint16 codes; empty ones carry MATLAB_empty)."""
    if ds.attrs.get("MATLAB_empty", 0):
        return ""
    return "".join(chr(c) for c in np.asarray(ds[()]).ravel(order="F"))


def _read73(path: str | Path, name: str) -> dict[str, Any]:
    with h5py.File(path, "r") as f:
        s = f[name]
        labeled = s["Trajectories"]["Labeled"]
        refs = np.asarray(labeled["Labels"][()]).ravel(order="F")
        labels = [mat73_text(f[r]).strip() for r in refs]
        data = np.asarray(labeled["Data"][()], dtype=np.float64).T      # undo MATLAB's order

        def opt(group: h5py.Group, key: str) -> Any:
            """A field's value: text for a MATLAB char array, else the array; None if absent."""
            if key not in group:
                return None
            ds = group[key]
            return mat73_text(ds) if ds.attrs.get("MATLAB_class") == b"char" else ds[()]

        return {
            "data": data,
            "labels": labels,
            "count": opt(labeled, "Count"),
            "rate": opt(s, "FrameRate"),
            "frames": opt(s, "Frames"),
            "start_frame": opt(s, "StartFrame"),
            "timestamp": mat73_text(s["Timestamp"]) if "Timestamp" in s else None,
        }


# ---------------------------------------------------------------------------- writing


def _struct_name(path: Path) -> str:
    """A MATLAB identifier from the file name, as QTM names the struct after the file."""
    name = re.sub(r"\W", "_", path.stem)
    return (name if name[:1].isalpha() else f"qtm_{name}")[:63]


def _export(series: MarkerSeries) -> tuple[np.ndarray, dict[str, Any]]:
    """Data (M x 4 x T, mm, NaN where missing) and the scalar fields of the QTM struct."""
    t, m = series.positions.shape[:2]
    data = np.empty((m, 4, t))
    data[:, :3, :] = series.positions.transpose(1, 2, 0) * 1e3
    res = np.zeros((t, m)) if series.residuals is None else series.residuals
    data[:, 3, :] = res.T * 1e3
    data[:, 3, :][np.isnan(data[:, :3, :]).any(axis=1)] = np.nan
    fields = {
        "StartFrame": float(series.meta.get("start_frame") or 1),
        "Frames": float(t),
        "FrameRate": float(series.rate_hz),
        "Timestamp": str(series.meta.get("timestamp") or ""),
    }
    return data, fields


def write_qtm_mat(path: str | Path, series: MarkerSeries, version: str = "7") -> None:
    """Write ``series`` as a QTM MAT export, MAT ``version`` "7" (scipy) or "7.3" (HDF5)."""
    if version not in ("7", "7.3"):
        raise ValueError(f"version must be '7' or '7.3', got {version!r}")
    path = Path(path)
    data, fields = _export(series)
    struct = {
        "File": path.name, **fields,
        "Trajectories": {"Labeled": {"Count": float(len(series.labels)),
                                     "Labels": list(series.labels), "Data": data}},
    }
    name = _struct_name(path)
    if version == "7.3":
        write_mat73(path, {name: struct})
        return
    labels = np.empty((1, len(series.labels)), dtype=object)           # a 1 x M cell
    labels[0, :] = list(series.labels)
    struct["Trajectories"]["Labeled"]["Labels"] = labels
    with atomic_output(path) as tmp, open(tmp, "wb") as fh:
        scipy.io.savemat(fh, {name: struct}, do_compression=True, oned_as="row")


def write_mat73(path: str | Path, variables: dict[str, Any]) -> None:
    """Write a MATLAB v7.3 MAT file laid out as MATLAB does (HDF5 behind a 512-byte userblock).

    Values: numbers and arrays (stored as double), ``str`` (char), a list of ``str`` (a 1 x n
    cell array of strings, stored as object references to uint16 char arrays under ``#refs#``)
    and ``dict`` (a 1 x 1 struct, recursively).
    """
    with atomic_output(path) as tmp:
        with h5py.File(tmp, "w", userblock_size=512) as f:
            for key, value in variables.items():
                _h5_value(f, key, value)
        with open(tmp, "r+b") as fh:
            fh.write(_matlab_header())


def _matlab_header() -> bytes:
    """The 512-byte userblock MATLAB puts before the HDF5 data of a v7.3 file."""
    text = (b"MATLAB 7.3 MAT-file, Platform: GLNXA64, Created on: Thu Jan  1 00:00:00 1970 "
            b"HDF5 schema 1.00 .")
    head = text.ljust(116, b" ") + b"\x00" * 8 + b"\x00\x02" + b"IM"
    return head.ljust(512, b"\x00")


def _h5_class(obj: h5py.HLObject, cls: str) -> None:
    obj.attrs["MATLAB_class"] = np.bytes_(cls)


def _h5_value(parent: h5py.Group, key: str, value: Any) -> h5py.HLObject:
    if isinstance(value, dict):
        g = parent.create_group(key)
        _h5_class(g, "struct")
        names = np.empty(len(value), dtype=object)
        names[:] = [np.frombuffer(k.encode(), dtype="S1") for k in value]
        g.attrs.create("MATLAB_fields", names, dtype=h5py.vlen_dtype(np.dtype("S1")))
        for k, v in value.items():
            _h5_value(g, k, v)
        return g
    if isinstance(value, str):
        return _h5_char(parent, key, value)
    if isinstance(value, list | tuple) and all(isinstance(v, str) for v in value):
        refs = parent.file.require_group("#refs#")
        cells = np.empty((len(value), 1), dtype=h5py.ref_dtype)        # 1 x n, reversed
        for i, text in enumerate(value):
            cells[i, 0] = _h5_char(refs, f"{key}_{len(refs)}", text).ref
        ds = parent.create_dataset(key, data=cells)
        _h5_class(ds, "cell")
        return ds
    arr = np.asarray(value, dtype=np.float64)
    arr = arr.reshape(1, 1) if arr.ndim == 0 else arr[None, :] if arr.ndim == 1 else arr
    ds = parent.create_dataset(key, data=arr.T)                         # MATLAB order reversed
    _h5_class(ds, "double")
    return ds


def _h5_char(parent: h5py.Group, key: str, text: str) -> h5py.Dataset:
    if not text:
        ds = parent.create_dataset(key, data=np.zeros(2, dtype=np.uint64))
        _h5_class(ds, "char")
        ds.attrs["MATLAB_empty"] = np.uint8(1)
        return ds
    codes = np.array([[ord(c)] for c in text], dtype=np.uint16)         # 1 x n, reversed
    ds = parent.create_dataset(key, data=codes)
    _h5_class(ds, "char")
    ds.attrs["MATLAB_int_decode"] = np.int32(2)
    return ds

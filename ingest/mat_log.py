"""MAT force logs (Level 4 and v7 through scipy.io, v7.3 through h5py) in the shapes Simulink
and the Speedgoat's tools save, each brought down to a :class:`~ingest.log_table.LogTable`:

- named columns: one vector per column, or one matrix and a ``columns`` / ``names`` cellstr;
- a Simulink To File array: time in the first row and one row per signal, no names (or the
  column form: time in the first column);
- To Workspace "Structure With Time": ``x.time`` and ``x.signals.values`` (N x k);
- ``SimulinkRealTime.utils.getFileScopeData`` saved as a struct: ``data`` (N x k) with time
  in the last column, optionally ``signalNames``;
- a model's default outputs ``tout`` and ``yout`` (an array or a Structure With Time).

Unnamed signals are numbered 1, 2, ... (time apart), and session.toml names them by number.
``force.variable`` picks the variable, or a field inside a struct by its path
(``force_log.signals.values``), where the file holds several candidates. MATLAB objects
(``timeseries``, ``Simulink.SimulationData.Dataset``, ``table``: MCOS data no Python reader
decodes) are refused in one line that names them and says how to save them as arrays.
"""

from __future__ import annotations

from dataclasses import dataclass
from pathlib import Path
from typing import Any

import h5py
import numpy as np
import scipy.io
from scipy.io.matlab import MatlabFunction, MatlabObject, MatlabOpaque

from core.errors import BadInput
from core.text import attr_text
from ingest.log_table import LogTable
from ingest.qtm_mat import mat73_text

_NAME_VARS = ("columns", "names", "column_names")
_SKIP = ("#refs#", "#subsystem#")
_NUMERIC_CLASSES = ("double", "single", "int8", "uint8", "int16", "uint16", "int32", "uint32",
                    "int64", "uint64", "logical")


@dataclass(frozen=True)
class MatObject:
    """A MATLAB object (MCOS or old-style class) that no Python reader decodes."""

    class_name: str


# ---------------------------------------------------------------------------- loading


def load_mat(path: str | Path, kind: str) -> dict[str, Any]:
    """Every variable of a MAT file as plain values: arrays in MATLAB's shape (2-D), text as
    str, cellstr as lists, structs as dicts, objects as :class:`MatObject`."""
    if kind in ("mat4", "mat5"):
        raw = scipy.io.loadmat(path, squeeze_me=False, struct_as_record=True,
                               chars_as_strings=True)
        return {_opaque_name(v) or k: _v7(v) for k, v in raw.items() if not k.startswith("__")}
    with h5py.File(path, "r") as f:
        return {k: _v73(f, f[k]) for k in f if k not in _SKIP}


def _v7(v: Any) -> Any:
    if isinstance(v, MatlabOpaque):
        return MatObject(_opaque_class(v))
    if isinstance(v, MatlabObject):
        return MatObject(str(v.classname))
    if isinstance(v, MatlabFunction):
        return MatObject("function_handle")
    if not isinstance(v, np.ndarray):
        return v
    if v.dtype.names:                                   # a struct, or a list of them
        if v.size == 0:
            return {n: np.zeros((0, 0)) for n in v.dtype.names}
        items = [{n: _v7(el[n]) for n in v.dtype.names} for el in v.ravel(order="F")]
        return items[0] if len(items) == 1 else items
    if v.dtype == object:                               # a cell array
        items = [_v7(x) for x in v.ravel(order="F")]
        return [x[0] if isinstance(x, list) and len(x) == 1 else x for x in items]
    if v.dtype.kind in "US":
        texts = [str(s).strip() for s in np.ravel(v)]
        return texts[0] if len(texts) == 1 else texts
    return v


def _opaque_name(v: Any) -> str | None:
    """An MCOS object's variable name (scipy keys it 'None' and keeps the name in s0)."""
    if not isinstance(v, MatlabOpaque):
        return None
    try:
        name = v[0]["s0"]
    except (IndexError, KeyError, ValueError, TypeError):
        return None
    return name.decode(errors="replace") if isinstance(name, bytes) and name else None


def _opaque_class(v: MatlabOpaque) -> str:
    for key in ("s2", "s1"):
        try:
            name = v[0][key]
        except (IndexError, KeyError, ValueError, TypeError):
            continue
        name = name.decode(errors="replace") if isinstance(name, bytes) else str(name)
        if name and name not in ("MCOS", "java", "handle"):
            return name
    return "MATLAB object"


def _v73(f: h5py.File, obj: h5py.HLObject) -> Any:
    cls = attr_text(obj.attrs.get("MATLAB_class", b""))
    if isinstance(obj, h5py.Group):
        if cls not in ("", "struct"):
            return MatObject(cls)
        return {k: _v73(f, obj[k]) for k in obj}
    if "MATLAB_object_decode" in obj.attrs or cls not in ("", "char", "cell", "struct",
                                                          *_NUMERIC_CLASSES):
        return MatObject(cls or "MATLAB object")
    if cls == "char":
        return mat73_text(obj)
    if cls == "cell" or obj.dtype == h5py.ref_dtype:
        items = [_v73(f, f[r]) for r in np.asarray(obj[()]).ravel(order="F")]
        return items
    if obj.attrs.get("MATLAB_empty", 0):
        return np.zeros((0, 0))
    return np.asarray(obj[()]).T                       # MATLAB stores dimensions reversed


# ---------------------------------------------------------------------------- layouts


def _is_array(v: Any) -> bool:
    return isinstance(v, np.ndarray) and v.dtype.kind in "iufb" and v.ndim <= 2 and v.size > 0


def _is_vector(v: Any) -> bool:
    return _is_array(v) and min(v.shape) == 1


def _is_matrix(v: Any) -> bool:
    return _is_array(v) and v.ndim == 2 and min(v.shape) > 1


def _get(path: str | Path, variables: dict[str, Any], where: str) -> Any:
    """The value at ``where`` ("x", "x.signals.values") of the file's variables."""
    node: Any = variables
    walked: list[str] = []
    for part in where.split("."):
        if not isinstance(node, dict) or part not in node:
            have = ", ".join(node) if isinstance(node, dict) else "no fields"
            at = ".".join(walked) or "the file"
            raise BadInput(path, f"force.variable {where!r}: {at} has no {part!r} (it has: "
                                 f"{have})")
        node = node[part]
        walked.append(part)
    return node


def _objects(variables: dict[str, Any], prefix: str = "") -> list[tuple[str, str]]:
    """(path, class) of every MATLAB object in the file, structs searched."""
    out = []
    for k, v in variables.items():
        if isinstance(v, MatObject):
            out.append((prefix + k, v.class_name))
        elif isinstance(v, dict):
            out += _objects(v, f"{prefix}{k}.")
    return out


def refuse_object(path: str | Path, name: str, class_name: str) -> BadInput:
    """The one line for a MATLAB object: what it is and how to save it as arrays."""
    how = {"timeseries": f"time = {name}.Time; values = {name}.Data",
           "table": f"values = table2array({name}); names = {name}.Properties.VariableNames",
           "timetable": f"time = seconds({name}.Time); values = {name}.Variables"}.get(
        class_name, f"time = {name}{{1}}.Values.Time; values = {name}{{1}}.Values.Data "
                    "(for a Dataset), or the object's arrays")
    return BadInput(path, f"{name} is a MATLAB {class_name} object, which no Python reader "
                          f"decodes; in MATLAB save it as arrays: {how}; save('log.mat', "
                          "'time', 'values') (or log with Save format 'Array' / 'Structure "
                          "With Time')")


def _signals(path: str | Path, values: Any, what: str) -> np.ndarray:
    """An N x k signal array (a vector is one signal)."""
    if isinstance(values, MatObject):
        raise refuse_object(path, what, values.class_name)
    if not _is_array(values):
        raise BadInput(path, f"{what} is not a numeric array")
    return values.reshape(-1, 1) if _is_vector(values) else values


def _numbered(fmt_name: str, time: np.ndarray, signals: np.ndarray, names: list[str] | None,
              details: dict[str, Any]) -> LogTable:
    """time plus signals named ``names`` or numbered 1..k."""
    k = signals.shape[1]
    if not names or len(names) != k or len(set(names)) != k or "time" in names:
        names = [str(i) for i in range(1, k + 1)]
    columns = {"time": np.ravel(time), **{n: signals[:, i] for i, n in enumerate(names)}}
    return LogTable(format="force_mat", columns=columns, time="time",
                    details={"layout": fmt_name, **details})


def _struct_with_time(path: str | Path, name: str, s: dict[str, Any]) -> LogTable:
    """To Workspace "Structure With Time": time, signals.values (signals may be several)."""
    sig = s["signals"]
    if isinstance(sig, dict) and isinstance(sig.get("values"), list):     # v7.3 struct array
        n = len(sig["values"])
        sig = [{k: v[i] if isinstance(v, list) and len(v) == n else v for k, v in sig.items()}
               for i in range(n)]
    parts = sig if isinstance(sig, list) else [sig]
    arrays, labels = [], []
    for i, p in enumerate(parts):
        if not isinstance(p, dict) or "values" not in p:
            raise BadInput(path, f"{name}.signals has no values field")
        arrays.append(_signals(path, p["values"], f"{name}.signals({i + 1}).values"))
        label = p.get("label")
        labels.append(label if isinstance(label, str) else "")
    values = np.hstack(arrays) if len(arrays) > 1 else arrays[0]
    block = s.get("blockName")
    details = {"variable": name, "signal_labels": labels,
               **({"block": block} if isinstance(block, str) else {})}
    if isinstance(s["time"], np.ndarray) and s["time"].size == 0:     # Save format "Structure"
        return LogTable(format="force_mat", details={"layout": "Structure (no time)", **details},
                        columns={str(i + 1): values[:, i] for i in range(values.shape[1])})
    time = _signals(path, s["time"], f"{name}.time")
    return _numbered("Structure With Time", time, values, None, details)


def _file_scope(path: str | Path, name: str, s: dict[str, Any]) -> LogTable:
    """getFileScopeData: data N x k, time in the last column; signalNames optional."""
    data = _signals(path, s["data"], f"{name}.data")
    if data.shape[1] < 2:
        raise BadInput(path, f"{name}.data has {data.shape[1]} column; getFileScopeData "
                             "writes the signals then time")
    names = s.get("signalNames")
    names = [names] if isinstance(names, str) else names
    names = [str(n).strip() for n in names] if isinstance(names, list) else None
    return _numbered("getFileScopeData", data[:, -1], data[:, :-1], names,
                     {"variable": name, "signal_names": names or []})


def _array(path: str | Path, name: str, m: np.ndarray) -> LogTable:
    """A To File array (time in the first row) or its column form (time in the first column)."""
    rising = [bool(np.all(np.diff(x) > 0)) for x in (m[0, :], m[:, 0])]
    rows = rising[0] if rising[0] != rising[1] else m.shape[0] < m.shape[1]
    a = m.T if rows else m
    return _numbered("To File array (time in the first row)" if rows else
                     "array (time in the first column)", a[:, 0], a[:, 1:], None,
                     {"variable": name})


def _named(path: str | Path, variables: dict[str, Any]) -> LogTable | None:
    """Named columns: vectors, or one matrix with a cellstr of column names."""
    vectors = {k: np.ravel(v) for k, v in variables.items() if _is_vector(v)}
    names_var = next((k for k in _NAME_VARS if isinstance(variables.get(k), list)), None)
    if names_var is None:
        return LogTable(format="force_mat", columns=vectors,
                        details={"layout": "named columns"}) if len(vectors) >= 2 else None
    names = [str(s).strip() for s in variables[names_var]]
    matrices = [v for v in variables.values() if _is_matrix(v) and len(names) in v.shape]
    if len(matrices) != 1:
        raise BadInput(path, f"{names_var} names {len(names)} columns but there is "
                             f"{'no' if not matrices else 'more than one'} matrix with that "
                             "many columns")
    m = matrices[0] if matrices[0].shape[1] == len(names) else matrices[0].T
    return LogTable(format="force_mat", columns={n: m[:, i] for i, n in enumerate(names)},
                    details={"layout": f"matrix with {names_var}"})


def _as_table(path: str | Path, name: str, v: Any) -> LogTable | None:
    """The layout of one variable (or struct field), or None when it is none we know."""
    if isinstance(v, MatObject):
        raise refuse_object(path, name, v.class_name)
    if isinstance(v, dict):
        if "time" in v and "signals" in v:
            return _struct_with_time(path, name, v)
        if "data" in v and _is_array(v["data"]):
            return _file_scope(path, name, v)
        return None
    if _is_matrix(v):
        return _array(path, name, v)
    return None


def _candidates(path: str | Path, variables: dict[str, Any]) -> dict[str, LogTable]:
    """Every variable that is a log by its shape."""
    out = {}
    for k, v in variables.items():
        if isinstance(v, MatObject) or k in ("tout", "yout"):
            continue
        t = _as_table(path, k, v)
        if t is not None:
            out[k] = t
    if "tout" in variables and "yout" in variables:
        out["yout"] = _tout_yout(path, variables)
    return out


def _tout_yout(path: str | Path, variables: dict[str, Any]) -> LogTable:
    """A model's default outputs: ``yout`` (an array, or a Structure With Time) timed by
    ``tout``, which session.toml's ``time_column`` may name."""
    yout = variables["yout"]
    if isinstance(yout, dict):
        t = _as_table(path, "yout", yout)
        if t is None:
            raise BadInput(path, "yout is a struct without time and signals")
    else:
        t = _numbered("tout + yout", _signals(path, variables["tout"], "tout"),
                      _signals(path, yout, "yout"), None, {"variable": "tout, yout"})
    if t.time is not None:
        t.time_alias = "tout"
    return t


def _at(path: str | Path, variables: dict[str, Any], variable: str) -> LogTable:
    """The log session.toml's ``force.variable`` names: a variable, a struct, or an array
    inside a Structure With Time (``x.signals.values``: timed by ``x.time``)."""
    v = _get(path, variables, variable)
    parts = variable.split(".")
    if _is_array(v) and len(parts) > 1:
        for i in range(len(parts) - 1, 0, -1):
            owner = _get(path, variables, ".".join(parts[:i]))
            if isinstance(owner, dict) and "time" in owner:
                return _numbered("Structure With Time", _signals(path, owner["time"],
                                                                 ".".join(parts[:i]) + ".time"),
                                 _signals(path, v, variable), None, {"variable": variable})
    t = _as_table(path, variable, v)
    if t is None:
        raise BadInput(path, f"force.variable {variable!r} is not a log (an array, a "
                             "Structure With Time or getFileScopeData struct)")
    return t


def read_mat_table(path: str | Path, kind: str, variable: str | None = None,
                   wanted: list[str] | None = None) -> LogTable:
    """The log in a MAT file: ``variable`` (a name or a struct path) where given; else named
    columns holding every ``wanted`` name, else the one variable shaped like a log."""
    variables = load_mat(path, kind)
    if variable is not None:
        return _at(path, variables, variable)
    named = _named(path, variables)
    if named is not None and (named.details["layout"] != "named columns" or (
            wanted and all(w in named.columns for w in wanted))):
        return named
    cands = _candidates(path, variables)
    if len(cands) == 1:
        return next(iter(cands.values()))
    if named is not None and not cands:
        return named
    objects = _objects(variables)
    if not cands and objects:
        raise refuse_object(path, *objects[0])
    if not cands:
        raise BadInput(path, "holds no log: no named columns, array, Structure With Time, "
                             "getFileScopeData struct or tout/yout (variables: "
                             f"{', '.join(variables) or 'none'})")
    raise BadInput(path, f"holds several logs ({', '.join(cands)}): name one with "
                         "force.variable in session.toml")

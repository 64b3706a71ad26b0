"""Damaged copies of the files the stages read, for the bad-input tests
(``tests/<package>/test_<stage>_bad_inputs.py``).

Each :class:`Mutation` edits a copy of a small valid file in place one way (truncated at several
offsets, a NaN or an inf in a numeric dataset, a dataset or attribute or key removed, a wrong
dtype or shape, an id out of range, JSON cut short, a value x1000 (mm or mN written as m or N),
an unsafe pickle) and states what must happen:

- ``REFUSE``: exit status 2, exactly one line on stderr naming the file, no output left;
- ``SAME``: refused as above, or the same output as from the clean file (a harmless change);
- ``VALID``: refused as above, or an output that passes its own validator (a change that means
  something the stage handles, e.g. a NaN marker sample is a gap).

Here are the edits, and the mutations of each file type read by more than one stage; a file
type one stage alone reads has its mutations in that stage's test.
"""

from __future__ import annotations

import json
import pickle
from collections.abc import Callable
from dataclasses import dataclass
from pathlib import Path
from typing import Any

import h5py
import numpy as np
import torch

from data_schema.hdf5 import H5Schema
from data_schema.states import STATES
from helpers.raw_sessions import analytic_session
from ingest.ingest_params import IngestParams
from ingest.mcap_io import write_raw_mcap

REFUSE, SAME, VALID = "refuse", "same", "valid"
CUTS = (0.02, 0.3, 0.6, 0.97)            # truncation points, as fractions of the file


@dataclass(frozen=True)
class Mutation:
    """One damaged copy: its name, how to make it (edits the file in place), what must happen."""

    name: str
    apply: Callable[[Path], None]
    expect: str = REFUSE


def truncations() -> list[Mutation]:
    """The file cut short at each of ``CUTS``."""
    def cut(frac: float) -> Callable[[Path], None]:
        def apply(p: Path) -> None:
            data = p.read_bytes()
            p.write_bytes(data[: min(int(len(data) * frac), len(data) - 1)])
        return apply
    return [Mutation(f"truncated at {frac:.0%}", cut(frac)) for frac in CUTS]


# --- HDF5 ---------------------------------------------------------------------------------------

def _rewrite(p: Path, name: str, fn: Callable[[np.ndarray], np.ndarray]) -> None:
    """Replace dataset ``name`` by ``fn(values)`` (any dtype or shape), keeping its attributes."""
    with h5py.File(p, "r+") as f:
        old = f[name]
        values, attrs = old[()], dict(old.attrs)
        del f[name]
        new = f.create_dataset(name, data=fn(values))
        new.attrs.update(attrs)


def set_at(index: tuple, value: float) -> Callable[[np.ndarray], np.ndarray]:
    """An array edit: a copy with ``value`` at ``index``."""
    def fn(v: np.ndarray) -> np.ndarray:
        v = v.copy()
        v[index] = value
        return v
    return fn


def edit_ds(name: str, fn: Callable[[np.ndarray], np.ndarray]) -> Callable[[Path], None]:
    """An HDF5 edit: dataset ``name`` replaced by ``fn`` of its values."""
    return lambda p: _rewrite(p, name, fn)


def del_attr(owner: str, attr: str) -> Callable[[Path], None]:
    """An HDF5 edit: attribute ``attr`` of group ``owner`` ("" for the root) deleted."""
    def apply(p: Path) -> None:
        with h5py.File(p, "r+") as f:
            del (f[owner] if owner else f).attrs[attr]
    return apply


def set_attr(owner: str, attr: str, value: Any) -> Callable[[Path], None]:
    """An HDF5 edit: attribute ``attr`` of group ``owner`` ("" for the root) set to ``value``."""
    def apply(p: Path) -> None:
        with h5py.File(p, "r+") as f:
            (f[owner] if owner else f).attrs[attr] = value
    return apply


def _del_ds(name: str) -> Callable[[Path], None]:
    def apply(p: Path) -> None:
        with h5py.File(p, "r+") as f:
            del f[name]
    return apply


def h5_mutations(path: Path, schema: H5Schema) -> list[Mutation]:
    """Mutations of every dataset and attribute of an HDF5 file, expectations from its layout."""
    out = truncations()
    with h5py.File(path, "r") as f:
        for entry in schema.datasets:
            name = entry.path.replace("*", sorted(f[entry.path.split("/*")[0]])[0]) \
                if "*" in entry.path else entry.path
            if name in f:
                out += _dataset_mutations(f[name], entry)
        for attr in f.attrs:
            out.append(Mutation(f"root attribute {attr} deleted", del_attr("", attr),
                                REFUSE if attr in (*schema.root_attrs, "schema") else VALID))
    return out


def _dataset_mutations(ds: h5py.Dataset, entry: Any) -> list[Mutation]:
    name, v = ds.name.lstrip("/"), ds[()]
    out = [
        Mutation(f"{name} removed", _del_ds(name), REFUSE if entry.required else VALID),
        Mutation(f"{name} with an extra axis", edit_ds(name, lambda a: a[..., None])),
    ]
    if v.dtype.kind in "fiub":
        other = {"f": np.int64, "i": np.float32, "u": np.float64, "b": np.uint8}[v.dtype.kind]
        out.append(Mutation(f"{name} as {np.dtype(other)}",
                            edit_ds(name, lambda a: a.astype(other))))
    if v.dtype.kind != "f" or v.size == 0:
        return out
    middle = np.unravel_index(v.size // 2, v.shape)
    nan_ok = VALID if not entry.finite else REFUSE
    out += [Mutation(f"NaN in {name}{list(middle)}", edit_ds(name, set_at(middle, np.nan)),
                     nan_ok),
            Mutation(f"inf in {name}{list(middle)}", edit_ds(name, set_at(middle, np.inf)),
                     REFUSE if entry.finite or entry.limit else VALID)]
    if entry.limit is not None:
        implausible = np.nanmax(np.abs(v)) * 1000 > entry.limit
        out.append(Mutation(f"{name} x1000 ({entry.units})", edit_ds(name, lambda a: a * 1000),
                            REFUSE if implausible else VALID))
    return out


def states_mutations(path: Path) -> list[Mutation]:
    """The layout's mutations and faults of meaning: ids out of range, odd attributes."""
    with h5py.File(path, "r") as f:
        s, e1 = len(f["states/force"]), len(f["single/start"])
    return h5_mutations(path, STATES) + [
        Mutation("single/start[0] past the states", edit_ds("single/start", set_at((0,), s + 5))),
        Mutation("multi/end[1] negative", edit_ds("multi/end", set_at((1,), -1))),
        Mutation("single/end[0] in another sequence", edit_ds("single/end", set_at((0,), s - 1))),
        Mutation("states/session[0] past session_names",
                 edit_ds("states/session", set_at((0,), 7))),
        Mutation("states/step[2] negative", edit_ds("states/step", set_at((2,), -1))),
        Mutation("single/start one row short", edit_ds("single/start", lambda a: a[: e1 - 1])),
        Mutation("units_length mm", set_attr("", "units_length", "mm")),
        Mutation("step_n negative", set_attr("", "step_n", -0.5)),
        Mutation("session_names not JSON", set_attr("", "session_names", "[dent")),
        Mutation("schema_version 1.0", set_attr("", "schema_version", "1.0")),
        Mutation("provenance edited", set_attr("", "provenance", '{"edited": 1}'), SAME),
    ]


# --- JSON ---------------------------------------------------------------------------------------

def edit_json(fn: Callable[[Any], Any]) -> Callable[[Path], None]:
    """A JSON edit: the document replaced by ``fn`` of it."""
    def apply(p: Path) -> None:
        doc = json.loads(p.read_text())
        p.write_text(json.dumps(fn(doc)))
    return apply


def with_key(keys: tuple, value: Any, append: bool = False) -> Callable[[Path], None]:
    """Set (or append to) ``doc[k0][k1]...``; ``value`` None deletes the key."""
    def fn(doc: Any) -> Any:
        obj = doc
        for k in keys[:-1]:
            obj = obj[k]
        if append:
            obj[keys[-1]].append(value)
        elif value is None:
            del obj[keys[-1]]
        else:
            obj[keys[-1]] = value
        return doc
    return edit_json(fn)


def json_cuts() -> list[Mutation]:
    """The JSON text cut short at each of ``CUTS``."""
    def cut(frac: float) -> Callable[[Path], None]:
        return lambda p: p.write_text(p.read_text()[: int(len(p.read_text()) * frac)])
    return [Mutation(f"JSON cut at {frac:.0%}", cut(frac)) for frac in CUTS]


def folds_mutations(path: Path) -> list[Mutation]:
    """Cut short, keys removed, ids out of range or in two roles, wrong types."""
    doc = json.loads(path.read_text())
    e1 = max(max(doc["folds"][0][r]["single"] or [0]) for r in ("train", "val", "test")) + 1
    val0, f0 = doc["folds"][0]["val"]["single"][0], ("folds", 0)
    return json_cuts() + [
        Mutation(f"key {k} removed", with_key((k,), None)) for k in doc if k != "note"
    ] + [
        Mutation("note removed", with_key(("note",), None)),
        Mutation("a list, not an object", edit_json(lambda d: d["folds"])),
        Mutation("note edited", with_key(("note",), "edited by hand"), SAME),
        Mutation("provenance emptied", with_key(("provenance",), {}), SAME),
        Mutation("seed x1000", with_key(("seed",), doc["seed"] * 1000), SAME),
        Mutation("train_subsets removed", with_key((*f0, "train_subsets"), None), SAME),
        Mutation("sha256 edited", with_key(("data", "sha256"), "0" * 64)),
        Mutation("group_by press", with_key(("group_by",), "press")),
        Mutation("no folds", with_key(("folds",), [])),
        Mutation("test.single id past the end", with_key((*f0, "test", "single"), e1 + 10**6,
                                                         append=True)),
        Mutation("test.multi id negative", with_key((*f0, "test", "multi"), -1, append=True)),
        Mutation("test.single id as text", with_key((*f0, "test", "single"), "3", append=True)),
        Mutation("test.single id 1.5", with_key((*f0, "test", "single"), 1.5, append=True)),
        Mutation("a val example also in test", with_key((*f0, "test", "single"), val0,
                                                        append=True)),
        Mutation("test.groups holds an unknown group", with_key((*f0, "test", "groups"), 999,
                                                                append=True)),
        Mutation("fold 0 without val", with_key((*f0, "val"), None)),
        Mutation("train_subsets of an unknown group",
                 with_key((*f0, "train_subsets"), [[999]])),
        Mutation("train_subsets not a list", with_key((*f0, "train_subsets"), 3)),
    ]


# --- checkpoints --------------------------------------------------------------------------------

def edit_ckpt(fn: Callable[[dict], Any]) -> Callable[[Path], None]:
    """A checkpoint edit: its state replaced by ``fn`` of it (a safe load, a torch save)."""
    def apply(p: Path) -> None:
        state = torch.load(p, weights_only=True)
        torch.save(fn(state), p)
    return apply


def in_state(keys: tuple, fn: Callable[[Any], Any]) -> Callable[[dict], dict]:
    """Replace ``state[k0][k1]...`` by ``fn(old)``; a result of ``...`` deletes the key."""
    def edit(state: dict) -> dict:
        obj = state
        for k in keys[:-1]:
            obj = obj[k]
        new = fn(obj.get(keys[-1]))
        if new is ...:
            del obj[keys[-1]]
        else:
            obj[keys[-1]] = new
        return state
    return edit


class PickledCall:
    """A pickled call: what a malicious checkpoint would carry."""

    def __reduce__(self) -> tuple:
        return (print, ("this must never run",))


def checkpoint_mutations(path: Path) -> list[Mutation]:
    """Cut short, unsafe, keys removed, weights non-finite or of another shape, odd config,
    normaliser or meta."""
    weights = list(torch.load(path, weights_only=True)["model"])
    first, last = weights[0], weights[-1]
    gone = lambda _: ...                              # noqa: E731 - reads as what it does
    out = truncations() + [
        Mutation("a pickled call", lambda p: torch.save({"model": PickledCall()}, p)),
        Mutation("plain pickle, not torch", lambda p: p.write_bytes(pickle.dumps([1, 2]))),
        Mutation("a list of tensors", edit_ckpt(lambda s: list(s["model"].values()))),
    ]
    out += [Mutation(f"key {k} removed", edit_ckpt(in_state((k,), gone)),
                     REFUSE if k in ("model", "config", "norm", "meta") else SAME)
            for k in ("model", "config", "norm", "meta", "optimizer", "epoch")]
    out += [
        Mutation(f"NaN in {first}", edit_ckpt(in_state(("model", first), lambda w: w * np.nan))),
        Mutation(f"inf in {last}", edit_ckpt(in_state(("model", last), lambda w: w + np.inf))),
        Mutation(f"{first} with an extra row",
                 edit_ckpt(in_state(("model", first), lambda w: torch.cat([w, w[:1]])))),
        Mutation(f"{last} removed", edit_ckpt(in_state(("model", last), gone))),
        Mutation("an extra weight", edit_ckpt(in_state(("model", "extra.weight"),
                                                       lambda _: torch.zeros(3)))),
        Mutation("config k = 1", edit_ckpt(in_state(("config", "k"), lambda _: 1))),
        Mutation("config without k", edit_ckpt(in_state(("config", "k"), gone))),
        Mutation("config widths halved", edit_ckpt(in_state(("config", "edge_widths"),
                                                            lambda w: [[c // 2 for c in x]
                                                                       for x in w]))),
        Mutation("norm scale 0", edit_ckpt(in_state(("norm", "scale"), lambda _: 0.0))),
        Mutation("norm force_scale NaN", edit_ckpt(in_state(("norm", "force_scale"),
                                                            lambda _: float("nan")))),
        Mutation("norm centre x1000 (mm)", edit_ckpt(in_state(("norm", "centre"),
                                                              lambda c: [x * 1000 for x in c]))),
        Mutation("norm force_scale x1000 (mN)", edit_ckpt(in_state(("norm", "force_scale"),
                                                                   lambda x: x * 1e6))),
        Mutation("meta without splits", edit_ckpt(in_state(("meta", "splits"), gone))),
        Mutation("meta fold as text", edit_ckpt(in_state(("meta", "options", "fold"),
                                                         lambda _: "0"))),
    ]
    return out


# --- raw MCAP -----------------------------------------------------------------------------------

def mcap_mutations(session_seed: int) -> list[Mutation]:
    """Byte damage, and sessions rewritten with damaged values (NaN in a marker is a gap)."""
    def values(edit: Callable[[Any], None]) -> Callable[[Path], None]:
        def apply(p: Path) -> None:
            session = analytic_session(session_seed, presses=2)
            edit(session)
            write_raw_mcap(p, session, {}, IngestParams().compression)
        return apply

    def flip(p: Path) -> None:
        data = bytearray(p.read_bytes())
        data[len(data) // 2] ^= 0xFF
        p.write_bytes(bytes(data))

    def at(obj: str, field: str, index: tuple, value: float) -> Callable[[Any], None]:
        return lambda s: getattr(getattr(s, obj), field).__setitem__(index, value)

    def scale(obj: str, field: str) -> Callable[[Any], None]:
        return lambda s: getattr(getattr(s, obj), field).__imul__(1000)

    def no_trigger(s: Any) -> None:
        s.force.trigger, s.trigger_event = None, None

    return truncations() + [
        Mutation("a byte flipped mid-file", flip),
        Mutation("NaN in a force sample", values(at("force", "values", (500, 2), np.nan))),
        Mutation("inf in a force sample", values(at("force", "values", (500, 0), np.inf))),
        Mutation("NaN in a trigger sample", values(at("force", "trigger", (50,), np.nan))),
        Mutation("inf in a marker", values(at("markers", "positions", (100, 3, 1), np.inf))),
        Mutation("NaN in a marker (a gap)", values(at("markers", "positions", (100, 3, 1),
                                                      np.nan)), VALID),
        Mutation("markers x1000 (mm)", values(scale("markers", "positions"))),
        Mutation("force x1000 (mN)", values(scale("force", "values"))),
        Mutation("trigger channel left out", values(no_trigger), VALID),
    ]

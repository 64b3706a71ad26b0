"""Every stage against damaged copies of every file it reads (seeded, fast).

For each (stage, file) pair a small valid file is built once, then mutated one way per case:
truncated at several offsets, a NaN or an inf in a numeric dataset, a dataset or attribute or
key removed, a wrong dtype or shape, an id out of range, JSON cut short, a value x1000 (mm or
mN written as m or N), an unsafe pickle. Each case states what must happen:

- ``REFUSE``: exit status 2, exactly one line on stderr naming the file, no output left;
- ``SAME``: refused as above, or the same output as from the clean file (a harmless change);
- ``VALID``: refused as above, or an output that passes its own validator (a change that means
  something the stage handles, e.g. a NaN marker sample is a gap).

No case may end in a traceback. The cases run are counted, and the count printed at the end.
"""

from __future__ import annotations

import json
import pickle
import shutil
from collections.abc import Callable
from dataclasses import dataclass, replace
from pathlib import Path
from typing import Any

import h5py
import numpy as np
import pytest
import torch
from cgnn_data import write_dent_states
from click.testing import CliRunner
from test_sync_stage import _session

from core.errors import BadInput
from core.provenance import sha256_file
from data_schema.hdf5 import H5Schema, read_h5
from data_schema.json_docs import validate_folds
from data_schema.states import STATES, validate_states
from data_schema.synced import PRESS_ATTRS, SYNCED, validate_synced
from ingest.mcap_io import write_raw_mcap
from pipeline.cli import cli

REFUSE, SAME, VALID = "refuse", "same", "valid"
CUTS = (0.02, 0.3, 0.6, 0.97)            # truncation points, as fractions of the file
COUNTS: dict[str, int] = {}              # (stage, file) -> cases run
PAIRS = 11
TINY_RUN = ("--epochs", "1", "--batch", "64", "--no-rrd")   # one optimiser step


@dataclass(frozen=True)
class Mutation:
    """One damaged copy: its name, how to make it (edits the file in place), what must happen."""

    name: str
    apply: Callable[[Path], None]
    expect: str = REFUSE


@dataclass(frozen=True)
class Outcome:
    """What a user sees of a command: exit status, stderr, and whether a traceback escaped."""

    exit_code: int
    stderr: str
    output: str
    exception: BaseException | None = None


@dataclass(frozen=True)
class Pair:
    """A stage and a file it reads: where a case's copy goes, how the stage runs on it, and what
    of its output must match the clean run's (``same``) or pass a check (``valid``)."""

    name: str
    clean: Path
    place: Callable[[Path], Path]                      # case folder -> path of the copy
    run: Callable[[Path, Path], tuple[Outcome, Path]]  # copy, case folder -> outcome, output
    same: Callable[[Path], Any]
    valid: Callable[[Path], Any]


def _cli(*args: object) -> Outcome:
    res = CliRunner().invoke(cli, ["-q", *map(str, args)])
    escaped = None if isinstance(res.exception, SystemExit) else res.exception
    return Outcome(res.exit_code, res.stderr, res.output, escaped)


# --- mutations of files -----------------------------------------------------------------------

def _truncations() -> list[Mutation]:
    def cut(frac: float) -> Callable[[Path], None]:
        def apply(p: Path) -> None:
            data = p.read_bytes()
            p.write_bytes(data[: min(int(len(data) * frac), len(data) - 1)])
        return apply
    return [Mutation(f"truncated at {frac:.0%}", cut(frac)) for frac in CUTS]


def _rewrite(p: Path, name: str, fn: Callable[[np.ndarray], np.ndarray]) -> None:
    """Replace dataset ``name`` by ``fn(values)`` (any dtype or shape), keeping its attributes."""
    with h5py.File(p, "r+") as f:
        old = f[name]
        values, attrs = old[()], dict(old.attrs)
        del f[name]
        new = f.create_dataset(name, data=fn(values))
        new.attrs.update(attrs)


def _set(index: tuple, value: float) -> Callable[[np.ndarray], np.ndarray]:
    def fn(v: np.ndarray) -> np.ndarray:
        v = v.copy()
        v[index] = value
        return v
    return fn


def _ds(name: str, fn: Callable[[np.ndarray], np.ndarray]) -> Callable[[Path], None]:
    return lambda p: _rewrite(p, name, fn)


def _del_attr(owner: str, attr: str) -> Callable[[Path], None]:
    def apply(p: Path) -> None:
        with h5py.File(p, "r+") as f:
            del (f[owner] if owner else f).attrs[attr]
    return apply


def _set_attr(owner: str, attr: str, value: Any) -> Callable[[Path], None]:
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
    out = _truncations()
    with h5py.File(path, "r") as f:
        for entry in schema.datasets:
            name = entry.path.replace("*", sorted(f[entry.path.split("/*")[0]])[0]) \
                if "*" in entry.path else entry.path
            if name in f:
                out += _dataset_mutations(f[name], entry)
        for attr in f.attrs:
            out.append(Mutation(f"root attribute {attr} deleted", _del_attr("", attr),
                                REFUSE if attr in (*schema.root_attrs, "schema") else VALID))
    return out


def _dataset_mutations(ds: h5py.Dataset, entry: Any) -> list[Mutation]:
    name, v = ds.name.lstrip("/"), ds[()]
    out = [
        Mutation(f"{name} removed", _del_ds(name), REFUSE if entry.required else VALID),
        Mutation(f"{name} with an extra axis", _ds(name, lambda a: a[..., None])),
    ]
    if v.dtype.kind in "fiub":
        other = {"f": np.int64, "i": np.float32, "u": np.float64, "b": np.uint8}[v.dtype.kind]
        out.append(Mutation(f"{name} as {np.dtype(other)}", _ds(name, lambda a: a.astype(other))))
    if v.dtype.kind != "f" or v.size == 0:
        return out
    middle = np.unravel_index(v.size // 2, v.shape)
    nan_ok = VALID if not entry.finite else REFUSE
    out += [Mutation(f"NaN in {name}{list(middle)}", _ds(name, _set(middle, np.nan)), nan_ok),
            Mutation(f"inf in {name}{list(middle)}", _ds(name, _set(middle, np.inf)),
                     REFUSE if entry.finite or entry.limit else VALID)]
    if entry.limit is not None:
        implausible = np.nanmax(np.abs(v)) * 1000 > entry.limit
        out.append(Mutation(f"{name} x1000 ({entry.units})", _ds(name, lambda a: a * 1000),
                            REFUSE if implausible else VALID))
    return out


def states_mutations(path: Path) -> list[Mutation]:
    """The layout's mutations and faults of meaning: ids out of range, odd attributes."""
    with h5py.File(path, "r") as f:
        s, e1 = len(f["states/force"]), len(f["single/start"])
    return h5_mutations(path, STATES) + [
        Mutation("single/start[0] past the states", _ds("single/start", _set((0,), s + 5))),
        Mutation("multi/end[1] negative", _ds("multi/end", _set((1,), -1))),
        Mutation("single/end[0] in another sequence", _ds("single/end", _set((0,), s - 1))),
        Mutation("states/session[0] past session_names", _ds("states/session", _set((0,), 7))),
        Mutation("states/step[2] negative", _ds("states/step", _set((2,), -1))),
        Mutation("single/start one row short", _ds("single/start", lambda a: a[: e1 - 1])),
        Mutation("units_length mm", _set_attr("", "units_length", "mm")),
        Mutation("step_n negative", _set_attr("", "step_n", -0.5)),
        Mutation("session_names not JSON", _set_attr("", "session_names", "[dent")),
        Mutation("schema_version 1.0", _set_attr("", "schema_version", "1.0")),
        Mutation("provenance edited", _set_attr("", "provenance", '{"edited": 1}'), SAME),
    ]


def synced_mutations(path: Path) -> list[Mutation]:
    """The layout's mutations and faults of meaning of a synced file's first press."""
    with h5py.File(path, "r") as f:
        frames, locations = len(f["presses/000/time_ns"]), len(f["locations/centre"])
        press_attrs = list(f["presses/000"].attrs)
    return h5_mutations(path, SYNCED) + [
        Mutation(f"presses/000 attribute {a} deleted", _del_attr("presses/000", a),
                 REFUSE if a in PRESS_ATTRS else VALID) for a in press_attrs
    ] + [
        Mutation("onset_index past the press", _set_attr("presses/000", "onset_index",
                                                        frames + 5)),
        Mutation("peak_index negative", _set_attr("presses/000", "peak_index", -1)),
        Mutation("location past locations/centre", _set_attr("presses/000", "location",
                                                             locations + 2)),
        Mutation("time_ns reversed", _ds("presses/000/time_ns", lambda a: a[::-1].copy())),
        Mutation("surface_normal not unit", _ds("calibration/surface_normal", lambda a: 2 * a)),
        Mutation("units_force mN", _set_attr("", "units_force", "mN")),
        Mutation("calibration attribute clock_method deleted",
                 _del_attr("calibration", "clock_method")),
    ]


def _edit_json(fn: Callable[[Any], Any]) -> Callable[[Path], None]:
    def apply(p: Path) -> None:
        doc = json.loads(p.read_text())
        p.write_text(json.dumps(fn(doc)))
    return apply


def _with(keys: tuple, value: Any, append: bool = False) -> Callable[[Path], None]:
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
    return _edit_json(fn)


def _json_cuts() -> list[Mutation]:
    def cut(frac: float) -> Callable[[Path], None]:
        return lambda p: p.write_text(p.read_text()[: int(len(p.read_text()) * frac)])
    return [Mutation(f"JSON cut at {frac:.0%}", cut(frac)) for frac in CUTS]


def folds_mutations(path: Path) -> list[Mutation]:
    """Cut short, keys removed, ids out of range or in two roles, wrong types."""
    doc = json.loads(path.read_text())
    e1 = max(max(doc["folds"][0][r]["single"] or [0]) for r in ("train", "val", "test")) + 1
    val0, f0 = doc["folds"][0]["val"]["single"][0], ("folds", 0)
    return _json_cuts() + [
        Mutation(f"key {k} removed", _with((k,), None)) for k in doc if k != "note"
    ] + [
        Mutation("note removed", _with(("note",), None)),
        Mutation("a list, not an object", _edit_json(lambda d: d["folds"])),
        Mutation("note edited", _with(("note",), "edited by hand"), SAME),
        Mutation("provenance emptied", _with(("provenance",), {}), SAME),
        Mutation("seed x1000", _with(("seed",), doc["seed"] * 1000), SAME),
        Mutation("train_subsets removed", _with((*f0, "train_subsets"), None), SAME),
        Mutation("sha256 edited", _with(("data", "sha256"), "0" * 64)),
        Mutation("group_by press", _with(("group_by",), "press")),
        Mutation("no folds", _with(("folds",), [])),
        Mutation("test.single id past the end", _with((*f0, "test", "single"), e1 + 10**6,
                                                      append=True)),
        Mutation("test.multi id negative", _with((*f0, "test", "multi"), -1, append=True)),
        Mutation("test.single id as text", _with((*f0, "test", "single"), "3", append=True)),
        Mutation("test.single id 1.5", _with((*f0, "test", "single"), 1.5, append=True)),
        Mutation("a val example also in test", _with((*f0, "test", "single"), val0,
                                                     append=True)),
        Mutation("test.groups holds an unknown group", _with((*f0, "test", "groups"), 999,
                                                             append=True)),
        Mutation("fold 0 without val", _with((*f0, "val"), None)),
        Mutation("train_subsets of an unknown group", _with((*f0, "train_subsets"), [[999]])),
        Mutation("train_subsets not a list", _with((*f0, "train_subsets"), 3)),
    ]


def _ckpt_edit(fn: Callable[[dict], Any]) -> Callable[[Path], None]:
    def apply(p: Path) -> None:
        state = torch.load(p, weights_only=True)
        torch.save(fn(state), p)
    return apply


def _in(keys: tuple, fn: Callable[[Any], Any]) -> Callable[[dict], dict]:
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


class _Call:
    """A pickled call: what a malicious checkpoint would carry."""

    def __reduce__(self) -> tuple:
        return (print, ("this must never run",))


def checkpoint_mutations(path: Path) -> list[Mutation]:
    """Cut short, unsafe, keys removed, weights non-finite or of another shape, odd config,
    normaliser or meta."""
    weights = list(torch.load(path, weights_only=True)["model"])
    first, last = weights[0], weights[-1]
    gone = lambda _: ...                              # noqa: E731 - reads as what it does
    out = _truncations() + [
        Mutation("a pickled call", lambda p: torch.save({"model": _Call()}, p)),
        Mutation("plain pickle, not torch", lambda p: p.write_bytes(pickle.dumps([1, 2]))),
        Mutation("a list of tensors", _ckpt_edit(lambda s: list(s["model"].values()))),
    ]
    out += [Mutation(f"key {k} removed", _ckpt_edit(_in((k,), gone)),
                     REFUSE if k in ("model", "config", "norm", "meta") else SAME)
            for k in ("model", "config", "norm", "meta", "optimizer", "epoch")]
    out += [
        Mutation(f"NaN in {first}", _ckpt_edit(_in(("model", first), lambda w: w * np.nan))),
        Mutation(f"inf in {last}", _ckpt_edit(_in(("model", last), lambda w: w + np.inf))),
        Mutation(f"{first} with an extra row", _ckpt_edit(_in(("model", first),
                                                              lambda w: torch.cat([w, w[:1]])))),
        Mutation(f"{last} removed", _ckpt_edit(_in(("model", last), gone))),
        Mutation("an extra weight", _ckpt_edit(_in(("model", "extra.weight"),
                                                   lambda _: torch.zeros(3)))),
        Mutation("config k = 1", _ckpt_edit(_in(("config", "k"), lambda _: 1))),
        Mutation("config without k", _ckpt_edit(_in(("config", "k"), gone))),
        Mutation("config widths halved", _ckpt_edit(_in(("config", "edge_widths"),
                                                        lambda w: [[c // 2 for c in x]
                                                                   for x in w]))),
        Mutation("norm scale 0", _ckpt_edit(_in(("norm", "scale"), lambda _: 0.0))),
        Mutation("norm force_scale NaN", _ckpt_edit(_in(("norm", "force_scale"),
                                                        lambda _: float("nan")))),
        Mutation("norm centre x1000 (mm)", _ckpt_edit(_in(("norm", "centre"),
                                                          lambda c: [x * 1000 for x in c]))),
        Mutation("norm force_scale x1000 (mN)", _ckpt_edit(_in(("norm", "force_scale"),
                                                               lambda x: x * 1e6))),
        Mutation("meta without splits", _ckpt_edit(_in(("meta", "splits"), gone))),
        Mutation("meta fold as text", _ckpt_edit(_in(("meta", "options", "fold"),
                                                     lambda _: "0"))),
    ]
    return out


def mcap_mutations(session_seed: int) -> list[Mutation]:
    """Byte damage, and sessions rewritten with damaged values (NaN in a marker is a gap)."""
    def values(edit: Callable[[Any], None]) -> Callable[[Path], None]:
        def apply(p: Path) -> None:
            session = _session(session_seed, presses=2)
            edit(session)
            write_raw_mcap(p, session, {})
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

    return _truncations() + [
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


def metrics_mutations(path: Path) -> list[Mutation]:
    """Cut short, tables removed, metrics non-finite, negative, in another unit or uncounted."""
    all0 = ("overall", 0, "metrics", "all")
    return _json_cuts() + [
        Mutation("runs removed", _with(("runs",), None)),
        Mutation("overall not a list", _with(("overall",), {})),
        Mutation("label a number", _with(("overall", 0, "label"), 3)),
        Mutation("folds removed", _with(("overall", 0, "folds"), None)),
        Mutation("metrics.all removed", _with(all0[:-1] + ("all",), None)),
        Mutation("ld_mean_mm NaN", _with((*all0, "ld_mean_mm"), float("nan"))),
        Mutation("force_mse_n2 inf", _with((*all0, "force_mse_n2"), float("inf"))),
        Mutation("force_abs_n negative", _with((*all0, "force_abs_n"), -0.1)),
        Mutation("n zero", _with((*all0, "n"), 0)),
        Mutation("ld_mean_mm x1000 (um)", _edit_json(lambda d: _scaled(d, all0, "ld_mean_mm"))),
        Mutation("ld_max_mm of run 0 as text", _with(("runs", 0, "metrics", "all",
                                                      "ld_max_mm"), "0.5")),
        Mutation("a key added", _with(("comment",), "by hand"), SAME),
    ]


def _scaled(doc: dict, keys: tuple, key: str) -> dict:
    """``doc`` with the metric ``key`` under ``keys`` multiplied by 1000."""
    obj = doc
    for k in keys:
        obj = obj[k]
    obj[key] *= 1000
    return doc


# --- judging a case -------------------------------------------------------------------------

def _judge(pair: Pair, m: Mutation, copy: Path, res: Outcome, out: Path, ref: Any
           ) -> str | None:
    """Why the case fails, or None."""
    if res.exception is not None:
        return f"traceback: {type(res.exception).__name__}: {res.exception}"
    if res.exit_code == 2:
        lines = res.stderr.strip().splitlines()
        if len(lines) != 1 or str(copy) not in lines[0] or "Traceback" in res.output:
            return f"exit 2 but stderr is not one line naming the file: {res.stderr!r}"
        if out.exists():
            return "refused, but left output behind"
        return None
    if m.expect == REFUSE:
        return f"exit {res.exit_code}, expected exit 2 (stderr {res.stderr[-300:]!r})"
    if res.exit_code != 0:
        return f"exit {res.exit_code}: {res.output[-300:]!r}"
    if m.expect == SAME and not _equal(pair.same(out), ref):
        return "accepted with an output that differs from the clean file's"
    try:
        pair.valid(out)
    except BadInput as e:
        return f"accepted with an output that fails its own check: {e}"
    return None


def _equal(a: Any, b: Any) -> bool:
    if isinstance(a, dict):
        return isinstance(b, dict) and a.keys() == b.keys() and all(_equal(a[k], b[k]) for k in a)
    if isinstance(a, np.ndarray | torch.Tensor):
        a, b = np.asarray(a), np.asarray(b)
        return np.array_equal(a, b, equal_nan=a.dtype.kind == "f")
    return a == b


def fuzz(pair: Pair, mutations: list[Mutation], tmp: Path) -> None:
    """Run every mutation of ``pair``'s file; fail with the list of cases that went wrong."""
    folder, copy = _case(pair, tmp / "clean")
    res, out = pair.run(copy, folder)
    assert res.exit_code == 0, res.output
    ref = pair.same(out)
    failures = []
    for i, m in enumerate(mutations):
        folder, copy = _case(pair, tmp / f"case{i:03d}")
        m.apply(copy)
        res, out = pair.run(copy, folder)
        why = _judge(pair, m, copy, res, out, ref)
        if why:
            failures.append(f"{pair.name}: {m.name}: {why}")
    COUNTS[pair.name] = len(mutations)
    assert not failures, f"{len(failures)} of {len(mutations)} cases failed:\n" + \
        "\n".join(failures)


def _case(pair: Pair, folder: Path) -> tuple[Path, Path]:
    """A fresh case folder holding a copy of the pair's clean file where the stage reads it."""
    folder.mkdir()
    copy = pair.place(folder)
    shutil.copyfile(pair.clean, copy)
    return folder, copy


# --- the valid inputs, built once ---------------------------------------------------------------

@pytest.fixture(scope="module")
def lab(tmp_path_factory) -> Path:
    """A two-press analytic session: MCAP -> synced file -> states (the lab path)."""
    d = tmp_path_factory.mktemp("lab")
    write_raw_mcap(d / "s.mcap", _session(0, presses=2), {})
    assert _cli("sync", d / "s.mcap", "--out", d / "synced.h5", "--no-rrd").exit_code == 0
    assert _cli("extract", d / "synced.h5", "--out", d / "st.h5", "--no-rrd").exit_code == 0
    return d


@pytest.fixture(scope="module")
def dent(tmp_path_factory) -> Path:
    """Dent states (6 presses), their 2-fold manifest, a one-step run, its metrics."""
    d = tmp_path_factory.mktemp("dent")
    write_dent_states(d / "states.h5", places=3, steps=4)
    for args in (("split", d / "states.h5", "--out", d / "splits.json", "--folds", "2",
                  "--ratio", "2:1:1", "--no-rrd"),
                 ("train", "--data", d / "states.h5", "--splits", d / "splits.json", "--out",
                  d / "run", *TINY_RUN),
                 ("eval", d / "run", "--out", d / "metrics.json", "--no-rrd")):
        res = _cli(*args)
        assert res.exit_code == 0, res.output
    return d


def _arrays(path: Path, schema: H5Schema) -> dict:
    if not path.exists():
        return {}
    arrays, attrs = read_h5(path, schema)
    return {**arrays, **{k: v for k, v in attrs.items() if "provenance" not in k}}


def _manifest(path: Path) -> dict:
    doc = json.loads(path.read_text())
    doc.pop("provenance")
    doc["data"].pop("sha256")
    return doc


def _weights(run: Path) -> dict:
    return torch.load(run / "best.pt", weights_only=True)["model"]


def _metrics(path: Path) -> dict:
    doc = json.loads(path.read_text())
    return {"overall": doc["overall"], "runs": [{**r, "run": None} for r in doc["runs"]]}


def _restamped(manifest: Path, data: Path, folder: Path) -> Path:
    """A copy of ``manifest`` carrying ``data``'s sha256, so the data's own check is reached."""
    doc = json.loads(manifest.read_text())
    doc["data"]["sha256"] = sha256_file(data)
    out = folder / "splits.json"
    out.write_text(json.dumps(doc))
    return out


def _run_pointing(clean: Path, folder: Path, data: Path | None = None,
                  splits: Path | None = None) -> Path:
    """A copy of the run ``clean`` in ``folder`` whose best.pt names other data or manifest
    files (each case of a pair puts its damaged copy there: one run serves them all)."""
    state = torch.load(clean / "best.pt", weights_only=True)
    if splits is not None:
        state["meta"]["splits"] = str(splits)
    if data is not None:
        state["meta"]["data"]["file"] = str(data)
    (folder / "run").mkdir(parents=True)
    torch.save(state, folder / "run" / "best.pt")
    return folder / "run"


def _train(data: Path, splits: Path, out: Path, *extra: object) -> Outcome:
    return _cli("train", "--data", data, "--splits", splits, "--out", out, *TINY_RUN, *extra)


# --- the pairs ----------------------------------------------------------------------------

def test_sync_reads_raw_mcap(lab, tmp_path) -> None:
    pair = Pair("sync <- raw MCAP", lab / "s.mcap", lambda c: c / "s.mcap",
                lambda p, c: (_cli("sync", p, "--out", c / "out.h5", "--no-rrd"), c / "out.h5"),
                lambda out: _arrays(out, SYNCED), validate_synced)
    fuzz(pair, mcap_mutations(0), tmp_path)


def test_extract_reads_synced(lab, tmp_path) -> None:
    pair = Pair("extract <- synced HDF5", lab / "synced.h5", lambda c: c / "synced.h5",
                lambda p, c: (_cli("extract", p, "--out", c / "out.h5", "--no-rrd"),
                              c / "out.h5"),
                lambda out: _arrays(out, STATES), validate_states)
    fuzz(pair, synced_mutations(lab / "synced.h5"), tmp_path)


def test_split_reads_states(dent, tmp_path) -> None:
    pair = Pair("split <- states", dent / "states.h5", lambda c: c / "states.h5",
                lambda p, c: (_cli("split", p, "--out", c / "out.json", "--folds", "2",
                                   "--ratio", "2:1:1", "--no-rrd"), c / "out.json"),
                _manifest, validate_folds)
    fuzz(pair, states_mutations(dent / "states.h5"), tmp_path)


def test_train_reads_states(dent, tmp_path) -> None:
    pair = Pair("train <- states", dent / "states.h5", lambda c: c / "states.h5",
                lambda p, c: (_train(p, _restamped(dent / "splits.json", p, c), c / "run"),
                              c / "run"),
                _weights, lambda run: _weights(run))
    fuzz(pair, states_mutations(dent / "states.h5"), tmp_path)


def test_train_reads_folds(dent, tmp_path) -> None:
    pair = Pair("train <- folds", dent / "splits.json", lambda c: c / "splits.json",
                lambda p, c: (_train(dent / "states.h5", p, c / "run"), c / "run"),
                _weights, _weights)
    fuzz(pair, folds_mutations(dent / "splits.json"), tmp_path)


def test_train_init_reads_checkpoint(dent, tmp_path) -> None:
    pair = Pair("train --init <- checkpoint", dent / "run" / "best.pt", lambda c: c / "init.pt",
                lambda p, c: (_train(dent / "states.h5", dent / "splits.json", c / "run",
                                     "--init", p), c / "run"),
                _weights, _weights)
    fuzz(pair, checkpoint_mutations(dent / "run" / "best.pt"), tmp_path)


def test_eval_reads_checkpoint(dent, tmp_path) -> None:
    pair = Pair("eval <- checkpoint", dent / "run" / "best.pt",
                lambda c: (c / "run").mkdir() or c / "run" / "best.pt",
                lambda p, c: (_cli("eval", p.parent, "--out", c / "m.json", "--no-rrd"),
                              c / "m.json"),
                _metrics, _metrics)
    fuzz(pair, checkpoint_mutations(dent / "run" / "best.pt"), tmp_path)


def test_eval_reads_folds(dent, tmp_path) -> None:
    live = tmp_path / "live"
    run = _run_pointing(dent / "run", live, splits=live / "splits.json")
    pair = Pair("eval <- folds", dent / "splits.json", lambda c: live / "splits.json",
                lambda p, c: (_cli("eval", run, "--out", c / "m.json", "--no-rrd"),
                              c / "m.json"),
                _metrics, _metrics)
    fuzz(pair, folds_mutations(dent / "splits.json"), tmp_path)


def test_eval_reads_states(dent, tmp_path) -> None:
    live = tmp_path / "live"
    run = _run_pointing(dent / "run", live, live / "states.h5", live / "splits.json")

    def evaluate(p: Path, c: Path) -> tuple[Outcome, Path]:
        _restamped(dent / "splits.json", p, live)
        return _cli("eval", run, "--out", c / "m.json", "--no-rrd"), c / "m.json"
    pair = Pair("eval <- states", dent / "states.h5", lambda c: live / "states.h5", evaluate,
                _metrics, _metrics)
    fuzz(pair, states_mutations(dent / "states.h5"), tmp_path)


def test_export_reads_checkpoint(dent, tmp_path) -> None:
    pair = Pair("export <- checkpoint", dent / "run" / "best.pt", lambda c: c / "best.pt",
                lambda p, c: (_cli("export", p, "--onnx", c / "m.onnx"), c / "m.onnx"),
                lambda out: out.stat().st_size, lambda out: out.stat().st_size)
    fuzz(pair, checkpoint_mutations(dent / "run" / "best.pt"), tmp_path)


def test_inspect_checks_metrics(dent, tmp_path) -> None:
    """inspect summarises a damaged file rather than refusing it: its verdict is the check."""
    def run(p: Path, c: Path) -> tuple[Outcome, Path]:
        res = _cli("inspect", p, "--json")
        verdict = json.loads(res.output)["details"].get("valid") if res.exit_code == 0 else ""
        if verdict != "valid" and res.exit_code == 0:     # reported as invalid: a refusal
            res = replace(res, exit_code=2, stderr=f"error: {p}: {verdict}\n")
        return res, c / "never"
    pair = Pair("inspect <- metrics JSON", dent / "metrics.json", lambda c: c / "metrics.json",
                run, lambda out: None, lambda out: None)
    fuzz(pair, metrics_mutations(dent / "metrics.json"), tmp_path)


def _refusal(folder: Path, clean: Path, mutation: Callable[[Path], None],
             args: Callable[[Path], tuple]) -> str:
    """The one line a stage prints for a damaged copy of ``clean``."""
    folder.mkdir()
    copy = folder / clean.name
    shutil.copyfile(clean, copy)
    mutation(copy)
    res = _cli(*args(copy))
    assert res.exit_code == 2 and res.exception is None, res.output
    return res.stderr.strip()


def test_each_message_names_the_dataset_index_or_key(lab, dent, tmp_path) -> None:
    """One refusal per file type, checked word for word where it matters."""
    out = tmp_path / "out"
    cases = [
        (lab / "s.mcap", next(m.apply for m in mcap_mutations(0) if m.name.startswith("force x")),
         lambda p: ("sync", p, "--out", out),
         "/force/raw block 3: sample 65: value Fz is 1017, more than a plausible 1000"),
        (lab / "synced.h5", _ds("presses/000/depth", lambda a: a * 1000),
         lambda p: ("extract", p, "--out", out), "presses/000/depth at frame 0 is "),
        (dent / "states.h5", _ds("states/force", _set((3,), np.nan)),
         lambda p: ("split", p, "--out", out), "states/force is not finite at index (3,) (nan)"),
        (dent / "splits.json", _with(("folds", 0, "test", "single"), 10**6, append=True),
         lambda p: ("train", "--data", dent / "states.h5", "--splits", p, "--out", out),
         "fold 0: test.single: example id 1000000 is outside the states file's"),
        (dent / "run" / "best.pt", lambda p: torch.save({"model": _Call()}, p),
         lambda p: ("export", p, "--onnx", out),
         "holds pickled code (print) that a safe load (weights_only) refuses"),
        (dent / "run" / "best.pt", _ckpt_edit(_in(("norm", "centre"),
                                                   lambda c: [x * 1000 for x in c])),
         lambda p: ("export", p, "--onnx", out), "checkpoint norm.centre is "),
    ]
    for i, (clean, mutation, args, words) in enumerate(cases):
        line = _refusal(tmp_path / f"m{i}", clean, mutation, args)
        assert line.startswith(f"error: {tmp_path / f'm{i}' / clean.name}") and words in line, \
            line


def test_count_of_cases(request) -> None:
    """Every pair ran: print how many cases over how many pairs."""
    if len(COUNTS) < PAIRS:
        pytest.skip(f"only {len(COUNTS)} of {PAIRS} pairs ran")
    line = f"fuzz: {sum(COUNTS.values())} mutation cases over {len(COUNTS)} (stage, file) pairs"
    plugins = request.config.pluginmanager
    with plugins.get_plugin("capturemanager").global_and_fixture_disabled():
        plugins.get_plugin("terminalreporter").write_line(line)
    assert sum(COUNTS.values()) >= 250

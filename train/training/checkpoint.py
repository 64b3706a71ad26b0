"""Checkpoints: one dict of plain types and tensors, read with weights_only (written atomically
by the train runner).

``{"model": state_dict, "optimizer": state_dict, "epoch": int, "best_val": float,
"config": CGNNConfig.to_dict(), "norm": Normaliser.to_dict(), "meta": {"options", "config",
"data": {"file", "sha256"}, "splits", "init", "variant"}, "provenance": {...}}``, and with
``--ema`` "trained": the weights the optimizer steps (``model`` is then their average), and in
``best.pt`` "intervals": the conformal table calibrated on the fold's validation presses
(:class:`train.intervals.table.IntervalTable`; absent from a run before them or without
validation):
everything inference needs travels with the weights, and nothing needs unpickling, so a
checkpoint from elsewhere cannot run code on load. ``provenance`` (:data:`SCHEMA`, written by
the train runner, :mod:`train.training.train_stage`) is how the file was made:
:func:`core.provenance.make_provenance`'s record (the command, the run's settings, the sha256
of the states file, the manifest and the --init checkpoint); a checkpoint from before it has
none. A checkpoint of an earlier version is read in today's form (:mod:`train.training.migrate`).
:func:`load_checkpoint` checks what it reads (weights of the network its config describes, all
finite; a usable normaliser; the run's meta) before any of it is used.
"""

from __future__ import annotations

import math
import pickle
import re
import warnings
from dataclasses import asdict
from pathlib import Path
from typing import Any

import torch

from core.errors import BadInput
from data_schema.hdf5 import SCALED_UNIT
from data_schema.states import PLAUSIBLE_M, PLAUSIBLE_N
from train.intervals.table import IntervalTable
from train.model.cgnn import CGNN
from train.model.config import CGNNConfig
from train.model.normalise import Normaliser
from train.training.migrate import migrate

SCHEMA = ("phantom.checkpoint", "1.0")     # the name and version its provenance records
REQUIRED = ("model", "config", "norm", "meta")
META_TYPES: dict[str, type | tuple[type, ...]] = {
    "options": dict, "config": dict, "data": dict, "splits": str, "init": (str, type(None))}


def load_checkpoint(path: str | Path, device: str | torch.device = "cpu") -> dict[str, Any]:
    """Read a checkpoint safely (``weights_only``) and check it; a damaged, foreign or unsafe
    file is bad input, in one line."""
    try:
        with warnings.catch_warnings():     # torch's own warning on a foreign pickle: our
            warnings.simplefilter("ignore")  # one line below says what is wrong
            state = torch.load(path, map_location=device, weights_only=True)
    except FileNotFoundError:
        raise BadInput(path, "no such checkpoint") from None
    except pickle.UnpicklingError as e:
        raise BadInput(path, _unsafe(e)) from None
    except Exception as e:  # noqa: BLE001 - torch raises many kinds for a damaged file
        raise BadInput(path, f"not a readable checkpoint ({type(e).__name__}: "
                             f"{_first_line(e)})") from None
    state = migrate(state)
    check_checkpoint(path, state)
    return state


def check_checkpoint(path: str | Path, state: Any) -> None:
    """Raise :class:`BadInput` naming the first key of ``state`` that is missing or wrong."""
    if not isinstance(state, dict):
        raise BadInput(path, f"not a checkpoint of `pipeline train` (holds a "
                             f"{type(state).__name__}, not a dict)")
    missing = [k for k in REQUIRED if k not in state]
    if missing:
        raise BadInput(path, f"not a checkpoint of `pipeline train`: lacks {missing}")
    config = _parsed(path, "config", CGNNConfig.from_dict, state["config"])
    norm = _parsed(path, "norm", Normaliser.from_dict, state["norm"])
    _check_norm(path, norm)
    _check_weights(path, state["model"], config)
    if "trained" in state:                           # a run that averages its weights
        _check_weights(path, state["trained"], config)
    _check_meta(path, state["meta"])
    if "intervals" in state:                         # absent: a run from before them
        _parsed(path, "intervals", IntervalTable.from_dict, state["intervals"])


def _parsed(path: str | Path, key: str, parse: Any, value: Any) -> Any:
    try:
        return parse(value)
    except BadInput as e:                 # the settings' own check: a value out of bounds
        raise BadInput(path, f"checkpoint {key}: {e.what}") from None
    except (KeyError, TypeError, ValueError, AttributeError) as e:
        raise BadInput(path, f"checkpoint key {key!r} is not usable "
                             f"({type(e).__name__}: {_first_line(e)})") from None


def _check_norm(path: str | Path, norm: Normaliser) -> None:
    """Finite, positive scales of plausible size in metres and newtons (not mm, mN)."""
    values = {"centre": (max(map(abs, norm.centre)), PLAUSIBLE_M, "m"),
              "scale": (norm.scale, PLAUSIBLE_M, "m"), "extent": (norm.extent, PLAUSIBLE_M, "m"),
              "disp_scale": (norm.disp_scale, PLAUSIBLE_M, "m"),
              "force_scale": (norm.force_scale, PLAUSIBLE_N, "N")}
    if norm.envelope is not None:           # the training envelope (signed: sizes only)
        values |= {f"envelope.{name}": (abs(value), PLAUSIBLE_N if "force" in name else
                                        PLAUSIBLE_M, "N" if "force" in name else "m")
                   for name, value in asdict(norm.envelope).items() if value is not None}
    for name, (value, limit, unit) in values.items():
        scale = name != "centre" and not name.startswith("envelope")
        if not math.isfinite(value) or (scale and value <= 0):
            raise BadInput(path, f"checkpoint norm.{name} is {value}: not a finite "
                                 + ("positive scale" if scale else "value"))
        if value > limit:
            raise BadInput(path, f"checkpoint norm.{name} is {value:.4g} {unit}, more than a "
                                 f"plausible {limit:g} {unit}: {SCALED_UNIT[unit]}?")


def _check_weights(path: str | Path, weights: Any, config: CGNNConfig) -> None:
    """The weights of exactly the network ``config`` describes, all finite."""
    with torch.device("meta"):                       # shapes only: nothing is allocated
        want = {k: tuple(v.shape) for k, v in CGNN(config).state_dict().items()}
    if not isinstance(weights, dict) or set(weights) != set(want):
        keys = set(weights) if isinstance(weights, dict) else set()
        odd = sorted(keys ^ set(want))[:3]
        raise BadInput(path, f"checkpoint model weights do not match its config (keys {odd})")
    for name, shape in want.items():
        w = weights[name]
        if not isinstance(w, torch.Tensor) or tuple(w.shape) != shape:
            got = tuple(w.shape) if isinstance(w, torch.Tensor) else type(w).__name__
            raise BadInput(path, f"checkpoint weight {name} is {got}, its config needs {shape}")
        if w.is_floating_point() and not bool(torch.isfinite(w).all()):
            raise BadInput(path, f"checkpoint weight {name} is not finite")


def _check_meta(path: str | Path, meta: Any) -> None:
    if not isinstance(meta, dict):
        raise BadInput(path, "checkpoint key 'meta' is not a dict")
    for key, kind in META_TYPES.items():
        if not isinstance(meta.get(key), kind):
            raise BadInput(path, f"checkpoint meta.{key} is missing or not of type {kind}")
    if not isinstance(meta["data"].get("file"), str) or \
            not isinstance(meta["options"].get("fold"), int):
        raise BadInput(path, "checkpoint meta lacks data.file or options.fold")


def _unsafe(e: Exception) -> str:
    """torch's several lines on a refused pickle, as one: what the file tried to load."""
    found = re.search(r"GLOBAL ([\w.]+)", str(e))
    if found is None:
        return ("not a torch checkpoint (a pickle that a safe load, weights_only, cannot "
                "read)")
    return (f"holds pickled code ({found.group(1)}) that a safe load (weights_only) refuses: "
            "not a checkpoint of `pipeline train`, and not run")


def _first_line(e: Exception) -> str:
    return next((line.strip() for line in str(e).splitlines() if line.strip()), "")


def model_from(state: dict[str, Any], device: str | torch.device = "cpu"
               ) -> tuple[CGNN, Normaliser]:
    """The model (eval mode) and normaliser a checkpoint holds."""
    model = CGNN(CGNNConfig.from_dict(state["config"])).to(device)
    model.load_state_dict(state["model"])
    return model.eval(), Normaliser.from_dict(state["norm"])

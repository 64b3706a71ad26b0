"""The generic model shipped with the package: the cGNN pre-trained once on MSM data drawn
from the prior (:mod:`sim.msm.msm_prior`), where every fold of every lab starts
(docs/model.md, "One pre-training for every lab").

A second file, ``generic_curved_model.pt`` (``--init generic-curved``), is that model pre-trained
again on the solids of curved moulds drawn from their prior (:mod:`sim.msm.mould_prior`): where a
curved lab starts (the demo's, with ``--shape``).

``pipeline train --init generic`` and ``pipeline demo`` (its default pre-training) read it; no
lab waits for a fit, a simulation or a pre-training before its first fine-tuning, and nothing
is downloaded. ``python scripts/build_generic.py`` rebuilds it from the prior and its own
recipe (:mod:`train.training.generic_recipe`, run by :mod:`pipeline.generic_build`): on the same
CPU kind and torch build, byte for byte (one thread; the file written from memory, with no time
or path of the machine that made it); on another, the same recipe to the rounding of that CPU's
kernels.

The file is a checkpoint of ``pipeline train`` (:mod:`train.training.checkpoint`) slimmed by
:func:`slim`: the averaged weights, the network, the normaliser, the intervals calibrated on
the prior's validation presses and the run's meta; no optimizer state, no second copy of the
weights (under 1 MB). Its ``provenance`` says how it was made: the build's commands, the
prior's ranges and the torch version.
"""

from __future__ import annotations

import hashlib
import io
import sys
from pathlib import Path
from typing import Any

import torch

NAME = "generic"                                  # what --init takes for the shipped file
SHIPPED = Path(__file__).with_name("generic_model.pt")
CURVED_NAME = "generic-curved"                    # ... and for the model for curved labs
SHIPPED_CURVED = Path(__file__).with_name("generic_curved_model.pt")
SCHEMA = ("phantom.generic_model", "1.0")         # its provenance record's name and version
KEEP = ("model", "config", "norm", "meta", "intervals", "epoch", "best_val", "best_epoch")


def resolve(init: str | Path) -> Path:
    """The checkpoint an ``--init`` names: the shipped generic model for ``NAME``, the one for
    curved labs for ``CURVED_NAME``, the path otherwise."""
    return {NAME: SHIPPED, CURVED_NAME: SHIPPED_CURVED}.get(str(init), Path(init))


def slim(state: dict[str, Any], provenance: dict[str, Any]) -> dict[str, Any]:
    """``state`` (a ``pipeline train`` checkpoint) as shipped: the keys inference and
    transfer learning read (:data:`KEEP`), the meta's paths as file names and without the
    prior's file digest (its bytes carry when it was made: no trace of the machine or the
    hour), and ``provenance`` in place of the run's."""
    out = {k: state[k] for k in KEEP if k in state}
    meta = dict(out["meta"])
    data = {k: v for k, v in meta["data"].items() if k != "sha256"}
    meta["data"] = {**data, "file": Path(data["file"]).name}
    meta["splits"] = Path(meta["splits"]).name
    if meta.get("init"):                   # the shipped model it started from: its name
        meta["init"] = Path(meta["init"]).name
    meta.pop("notes", None)
    out["meta"] = meta
    out["provenance"] = {"schema": SCHEMA[0], "schema_version": SCHEMA[1], **provenance}
    return out


def to_bytes(state: dict[str, Any]) -> bytes:
    """The file's bytes, saved from memory (``torch.save`` names the archive's folder after
    the file it writes to) and from :func:`canonical` objects: bytes that depend on the
    content only."""
    buf = io.BytesIO()
    torch.save(canonical(state), buf)
    return buf.getvalue()


def canonical(value: Any) -> Any:
    """``value`` rebuilt so that pickling it depends on its content only: pickle writes an
    object seen before as a reference to it, so two equal checkpoints whose dicts or
    tensors were shared differently (a config held twice, or once) would pickle apart.
    Every container and tensor is made anew, and equal strings are made one object."""
    if isinstance(value, dict):
        return {canonical(k): canonical(v) for k, v in value.items()}
    if isinstance(value, list | tuple):
        return type(value)(canonical(v) for v in value)
    if isinstance(value, str):
        return sys.intern(value)
    if isinstance(value, torch.Tensor):
        return value.detach().clone()
    return value


def weights_sha256(state: dict[str, Any]) -> str:
    """A digest of the model's weights (names, shapes and bytes, in order): what two builds
    agree on when they made the same model."""
    h = hashlib.sha256()
    for name, t in state["model"].items():
        h.update(name.encode())
        h.update(str(tuple(t.shape)).encode())
        h.update(t.detach().contiguous().cpu().numpy().tobytes())
    return h.hexdigest()

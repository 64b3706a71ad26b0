"""Checkpoints written by earlier versions, read in today's form: the one place that knows the
older forms, so no other module asks "from before?".

:func:`migrate` rewrites a loaded checkpoint (a dict of plain types and tensors) before it is
checked, case by case:

1. the network's config (``config`` and ``meta.config``) with ``tip_offsets`` (bool) and
   ``head_offsets`` (int), or neither (before either existed), becomes ``offsets`` ("none",
   "graph" or "heads") and ``offset_width``;
2. the heads' offset encoder's weights, once named ``offsets.*``, are ``encoder.*`` (in
   ``model`` and in ``trained``);
3. the normaliser without a training envelope, or an envelope without ``top``, gets them as
   None (unknown: the predictor then skips those checks);
4. ``meta.options`` lacking a training option that was added later gets its default (what
   such a run trained with), so a resumed run compares like with like;
5. ``meta.variant`` lacking ``offsets`` (before they were recorded) gets its network's; a
   pretrained variant lacking them gets the run's own (fine-tuning keeps the network);
6. ``meta`` without a ``variant`` at all (before variants were recorded) gets the one its
   config, options, states file and ``--init`` checkpoint describe.

Metrics documents need none: ``phantom.metrics`` 1.0 to 1.6 differ only by optional fields
(1.1 ``offsets``, 1.2 ``intervals``, ..., 1.6 a variant's ``rotate_force``), which
:mod:`data_schema.json_docs` checks where present. A checkpoint from before intervals needs
none either: it has no ``intervals`` and is used without them (:class:`train.Predictor`
refuses a ``level`` for it in one line).
"""

from __future__ import annotations

import warnings
from pathlib import Path
from typing import Any

import torch

from core.errors import BadInput
from train.model.config import OFFSET_WIDTH, CGNNConfig
from train.training.train_params import TrainOptions
from train.training.variant import make_variant

OLD_ENCODER = "offsets."      # the encoder's weights' prefix before it was named ``encoder``


def migrate(state: Any) -> Any:
    """``state`` (a loaded checkpoint) in today's form; anything that is not a dict, or lacks
    what a case reads, is left for the checks to refuse."""
    if not isinstance(state, dict):
        return state
    if isinstance(state.get("config"), dict):
        state["config"] = _config(state["config"])
    for key in ("model", "trained"):
        if isinstance(state.get(key), dict):
            state[key] = _weights(state[key])
    if isinstance(state.get("norm"), dict):
        state["norm"] = _norm(state["norm"])
    if isinstance(state.get("meta"), dict) and isinstance(state["meta"].get("config"), dict):
        state["meta"] = _meta(state["meta"])
    return state


def _config(config: dict) -> dict:
    """Case 1: where the network reads the offsets, as one field and its width."""
    if "offsets" in config:
        return config
    old = {k: config[k] for k in ("tip_offsets", "head_offsets") if k in config}
    width = int(old.get("head_offsets", 0))
    offsets = "graph" if old.get("tip_offsets") else "heads" if width else "none"
    rest = {k: v for k, v in config.items() if k not in old}
    return {**rest, "offsets": offsets, "offset_width": width or OFFSET_WIDTH}


def _weights(weights: dict) -> dict:
    """Case 2: the encoder's weights under today's name."""
    return {("encoder." + k[len(OLD_ENCODER):] if k.startswith(OLD_ENCODER) else k): v
            for k, v in weights.items()}


def _norm(norm: dict) -> dict:
    """Case 3: an envelope, and its ``top``, that were not kept are None (any other field
    missing is damage, left for the checks to refuse)."""
    env = norm.get("envelope")
    if isinstance(env, dict):
        env = {"top": None, **env}
    return {**norm, "envelope": env}


def _meta(meta: dict) -> dict:
    """Cases 4 to 6: the run's options, config and variant."""
    meta = {**meta, "config": _config(meta["config"])}
    if isinstance(meta.get("options"), dict):
        meta["options"] = {**TrainOptions().to_dict(), **meta["options"]}
    own = meta["config"]["offsets"]
    if isinstance(meta.get("variant"), dict):
        meta["variant"] = _variant(meta["variant"], own)
    elif isinstance(meta.get("options"), dict) and isinstance(meta.get("data"), dict):
        meta["variant"] = make_variant(
            CGNNConfig.from_dict(meta["config"]), TrainOptions.from_dict(meta["options"]),
            meta["data"].get("file", ""), _init_meta(meta)).to_dict()
    return meta


def _variant(variant: dict, offsets: str) -> dict:
    """Case 5: a variant, and the one it was fine-tuned from, with where they read offsets."""
    variant = {**variant, "offsets": variant.get("offsets", offsets)}
    if isinstance(variant.get("pretrained"), dict):
        variant["pretrained"] = _variant(variant["pretrained"], variant["offsets"])
    return variant


def _init_meta(meta: dict) -> dict | None:
    """Case 6: the meta of the checkpoint a run started from, in today's form (None for a
    run trained from scratch)."""
    init = meta.get("init")
    if not init:
        return None
    try:
        with warnings.catch_warnings():
            warnings.simplefilter("ignore")
            state = torch.load(Path(init), map_location="cpu", weights_only=True)
        return migrate(state)["meta"]
    except Exception as e:  # noqa: BLE001 - any unreadable file: said in one line
        raise BadInput(init, "the --init checkpoint of a run from before variants were "
                             f"recorded cannot be read, so its variant is unknown "
                             f"({type(e).__name__})") from None

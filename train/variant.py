"""A run's variant as structured fields, recorded in its checkpoint when it is trained.

What Table 2 calls a run ("cGNN/aug MSM (TL)") is built from these fields for display only;
nothing parses a label back. The fields: ``model`` ("cGNN", or "noCond" without the
condition), ``train_data`` ("MSM" or "Exp", from the states file's ``source``), ``rotate`` and
``aug`` (rotation augmentation; a point fraction), and ``pretrained``: None, or the variant of
the run it was fine-tuned from (transfer learning).
"""

from __future__ import annotations

from pathlib import Path

import h5py

from data_schema.hdf5 import attr_text
from train.checkpoint import load_checkpoint

SOURCE_NAMES = {"msm": "MSM", "lab": "Exp"}


def source_name(data: str | Path) -> str:
    """'MSM' or 'Exp' for a states file; '?' where it cannot be read (a moved file)."""
    try:
        with h5py.File(data, "r") as f:
            source = attr_text(f.attrs["source"])
    except (OSError, KeyError):
        return "?"
    return SOURCE_NAMES.get(source, source)


def make_variant(config: dict, options: dict, data: str | Path, init_meta: dict | None
                 ) -> dict:
    """The variant of a run with this network ``config``, training ``options`` and data,
    fine-tuned from the run whose checkpoint meta is ``init_meta`` (or trained from scratch)."""
    return {"model": "cGNN" if config["use_condition"] else "noCond",
            "train_data": source_name(data), "rotate": bool(options.get("rotate")),
            "aug": bool(options.get("point_fraction")),
            "pretrained": None if init_meta is None else recorded_variant(init_meta)}


def recorded_variant(meta: dict) -> dict:
    """The variant a checkpoint's meta records (derived for checkpoints older than the field)."""
    if isinstance(meta.get("variant"), dict):
        return meta["variant"]
    init = None
    if meta.get("init"):                  # an old run: read the one it started from
        init = load_checkpoint(meta["init"])["meta"]
    return make_variant(meta["config"], meta["options"], meta["data"]["file"], init)


def label(v: dict) -> str:
    """The Table 2 name: model/train set, or model/pre-training set (TL) when fine-tuned."""
    if v["pretrained"]:
        p = v["pretrained"]
        return f"{v['model']}/{'aug ' if p['aug'] else ''}{p['train_data']} (TL)"
    return f"{v['model']}/{'rot ' if v['rotate'] else ''}{'aug ' if v['aug'] else ''}" \
           f"{v['train_data']}"

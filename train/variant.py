"""A run's variant as structured fields, recorded in its checkpoint when it is trained.

:class:`Variant` is what evaluation groups runs by: two runs are pooled only when every field
is the same. What Table 2 calls a run ("cGNN/aug MSM (TL)", :attr:`Variant.label`) is built
from these fields for display only; nothing parses a label back, and nothing groups by it (a
fine-tuned run's label leaves out its own rotation and aug). The fields: ``model`` ("cGNN", or
"noCond" without the condition), ``train_data`` ("MSM" or "Exp", from the states file's
``source``), ``rotate`` and ``aug`` (rotation augmentation; a point fraction), and
``pretrained``: None, or the variant of the run it was fine-tuned from (transfer learning).
A checkpoint's meta and ``metrics.json`` keep it as a plain dict of the same fields
(:meth:`Variant.to_dict`).
"""

from __future__ import annotations

from dataclasses import dataclass
from pathlib import Path

import h5py

from data_schema.hdf5 import attr_text
from train.checkpoint import load_checkpoint


@dataclass(frozen=True)
class Variant:
    """One variant of the paper's Table 2 (hashable: runs are grouped by it)."""

    model: str
    train_data: str
    rotate: bool
    aug: bool
    pretrained: Variant | None = None

    def to_dict(self) -> dict:
        """The plain form kept in a checkpoint's meta and in ``metrics.json``."""
        return {"model": self.model, "train_data": self.train_data, "rotate": self.rotate,
                "aug": self.aug,
                "pretrained": None if self.pretrained is None else self.pretrained.to_dict()}

    @classmethod
    def from_dict(cls, d: dict) -> Variant:
        return cls(str(d["model"]), str(d["train_data"]), bool(d["rotate"]), bool(d["aug"]),
                   cls.from_dict(d["pretrained"]) if d.get("pretrained") else None)

    @property
    def label(self) -> str:
        """The Table 2 name: model/train set, or model/pre-training set (TL) when
        fine-tuned. For display only: a fine-tuned run's leaves out its own fields."""
        if self.pretrained:
            p = self.pretrained
            return f"{self.model}/{'aug ' if p.aug else ''}{p.train_data} (TL)"
        return self._own

    @property
    def full_name(self) -> str:
        """A name that says every field ("cGNN/rot Exp from cGNN/aug MSM"): shown where two
        variants share a label."""
        return self._own + (f" from {self.pretrained.full_name}" if self.pretrained else "")

    @property
    def _own(self) -> str:
        return f"{self.model}/{'rot ' if self.rotate else ''}{'aug ' if self.aug else ''}" \
               f"{self.train_data}"


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
    fine-tuned from the run whose checkpoint meta is ``init_meta`` (or trained from scratch),
    in the plain form its checkpoint keeps."""
    return _variant(config, options, data, init_meta).to_dict()


def _variant(config: dict, options: dict, data: str | Path, init_meta: dict | None
             ) -> Variant:
    return Variant("cGNN" if config["use_condition"] else "noCond", source_name(data),
                   bool(options.get("rotate")), bool(options.get("point_fraction")),
                   None if init_meta is None else recorded_variant(init_meta))


def recorded_variant(meta: dict) -> Variant:
    """The variant a checkpoint's meta records (derived for checkpoints older than the field)."""
    if isinstance(meta.get("variant"), dict):
        return Variant.from_dict(meta["variant"])
    init = None
    if meta.get("init"):                  # an old run: read the one it started from
        init = load_checkpoint(meta["init"])["meta"]
    return _variant(meta["config"], meta["options"], meta["data"]["file"], init)

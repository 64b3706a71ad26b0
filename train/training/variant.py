"""A run's variant as structured fields, recorded in its checkpoint when it is trained.

:class:`Variant` is what evaluation groups runs by: two runs are pooled only when every field
is the same. What Table 2 calls a run ("cGNN/aug MSM (TL)", :attr:`Variant.label`) is built
from these fields for display only; nothing parses a label back, and nothing groups by it (a
fine-tuned run's label leaves out its own rotation and aug). The fields: ``model`` ("cGNN", or
"noCond" without the condition), ``train_data`` ("MSM", "Solid", "Moulds" or "Exp", from the
states file's ``source``), ``rotate`` and ``aug`` (rotation augmentation; a point fraction),
``pretrained``: None, or the variant of the run it was fine-tuned from (transfer learning),
``offsets``: where the network reads the tip's offsets
(:class:`train.model.config.Offsets`), and ``rotate_force``: False where the rotation left the
force's examples unturned (``train --no-rotate-force``, which needs the rotation).
A checkpoint's meta and ``metrics.json`` keep it as a plain dict of the same fields
(:meth:`Variant.to_dict`); a checkpoint's older forms are read through
:mod:`train.training.migrate`.
"""

from __future__ import annotations

from dataclasses import dataclass
from pathlib import Path
from typing import Any

from core.errors import BadInput
from data_schema.metrics_doc import VariantRow
from data_schema.states import states_source
from train.model.config import CGNNConfig, Offsets
from train.training.train_params import TrainOptions

OFFSET_NAMES = {Offsets.GRAPH: "tip offsets", Offsets.HEADS: "head offsets"}


@dataclass(frozen=True)
class Variant:
    """One variant of the paper's Table 2 (hashable: runs are grouped by it)."""

    model: str
    train_data: str
    rotate: bool
    aug: bool
    pretrained: Variant | None = None
    offsets: Offsets = Offsets.NONE
    rotate_force: bool = True

    def to_dict(self) -> dict[str, Any]:
        """The plain form kept in a checkpoint's meta and in ``metrics.json`` (its keys are
        :class:`~data_schema.metrics_doc.VariantRow`'s)."""
        return self.row().to_json()

    def row(self) -> VariantRow:
        """As the documents write it."""
        return VariantRow(self.model, self.train_data, self.rotate, self.aug,
                          None if self.pretrained is None else self.pretrained.row(),
                          self.offsets.value, None if self.rotate_force else False)

    @classmethod
    def from_dict(cls, d: dict[str, Any]) -> Variant:
        """From :meth:`to_dict`'s form."""
        return cls.from_row(VariantRow.from_json(d))

    @classmethod
    def from_row(cls, row: VariantRow) -> Variant:
        """From a document's row (its offsets required: :mod:`train.training.migrate` gives
        an old checkpoint's its network's)."""
        if row.offsets is None:
            raise KeyError("offsets")
        return cls(str(row.model), str(row.train_data), bool(row.rotate), bool(row.aug),
                   cls.from_row(row.pretrained) if row.pretrained else None,
                   Offsets(row.offsets), row.rotate_force is not False)

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
        """A name that says every field ("cGNN/rot Exp from cGNN/aug MSM", "with head
        offsets" where it has them): shown where two variants share a label."""
        own = self._own + (f" with {OFFSET_NAMES[self.offsets]}" if self.offsets in
                           OFFSET_NAMES else "")
        return own + (f" from {self.pretrained.full_name}" if self.pretrained else "")

    @property
    def _own(self) -> str:
        rot = ("rot " if self.rotate_force else "rot (force unturned) ") if self.rotate else ""
        return f"{self.model}/{rot}{'aug ' if self.aug else ''}{self.train_data}"


SOURCE_NAMES = {"msm": "MSM", "solid": "Solid", "moulds": "Moulds", "lab": "Exp"}


def source_name(data: str | Path) -> str:
    """'MSM', 'Solid', 'Moulds' or 'Exp' for a states file; '?' where it cannot be read (a moved
    file) or names no source."""
    try:
        source = states_source(data)
    except BadInput:                # not readable (h5_reading names the file)
        return "?"
    return SOURCE_NAMES.get(source, source or "?")


def make_variant(config: CGNNConfig, opts: TrainOptions, data: str | Path,
                 init_meta: dict | None) -> Variant:
    """The variant of a run with this network, training options and data, fine-tuned from the
    run whose checkpoint meta is ``init_meta`` (or trained from scratch)."""
    return Variant("cGNN" if config.use_condition else "noCond", source_name(data),
                   opts.rotate, bool(opts.point_fraction),
                   None if init_meta is None else recorded_variant(init_meta), config.offsets,
                   opts.rotate_force)


def recorded_variant(meta: dict) -> Variant:
    """The variant a checkpoint's meta records."""
    return Variant.from_dict(meta["variant"])

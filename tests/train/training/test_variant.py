"""A run's variant records where its network reads the tip's offsets, so that evaluation
never pools the paper's network with one whose graph layers read the press."""

from __future__ import annotations

from dataclasses import replace

import pytest

from data_schema.metrics_doc import OFFSETS
from train.model.config import CGNNConfig, Offsets
from train.training.migrate import migrate
from train.training.train_params import TrainOptions
from train.training.variant import Variant, make_variant, recorded_variant


@pytest.mark.parametrize(("config", "offsets", "reads"), [
    (CGNNConfig(), "none", False),
    (CGNNConfig(offsets="graph"), "graph", True),
    (CGNNConfig(offsets="heads"), "heads", False),
])
def test_the_variant_says_where_the_offsets_enter(tmp_path, config, offsets, reads) -> None:
    variant = make_variant(config, TrainOptions(rotate=True), tmp_path / "gone.h5", None)
    recorded = variant.to_dict()
    assert recorded["offsets"] == offsets and type(recorded["offsets"]) is str
    assert variant.offsets is Offsets(offsets)
    assert variant.offsets.press_independent is not reads
    tuned = make_variant(config, TrainOptions(), tmp_path / "gone.h5",
                         {"variant": recorded, "config": config.to_dict()})
    assert tuned.pretrained == variant and tuned.offsets is Offsets(offsets)


def test_a_record_from_before_the_field_reads_its_network() -> None:
    """A checkpoint's variant without ``offsets`` takes them from its network's config (in
    the form before ``offsets`` was one field), and so does the run it was fine-tuned from
    (the same network)."""
    old = {"model": "cGNN", "train_data": "Exp", "rotate": True, "aug": False,
           "pretrained": {"model": "cGNN", "train_data": "MSM", "rotate": True, "aug": False,
                          "pretrained": None}}
    config = {k: v for k, v in CGNNConfig().to_dict().items()
              if k not in ("offsets", "offset_width")}
    meta = {"variant": old, "config": {**config, "tip_offsets": True, "head_offsets": 0}}
    variant = recorded_variant(migrate({"meta": meta})["meta"])
    assert variant.offsets == variant.pretrained.offsets == "graph"
    assert recorded_variant(migrate({"meta": {**meta, "config": config}})["meta"]).offsets \
        == "none"


def test_networks_that_differ_only_in_their_offsets_are_told_apart() -> None:
    a = Variant("cGNN", "Exp", True, False, None, "graph")
    b = Variant("cGNN", "Exp", True, False, None, "heads")
    assert a != b and a.label == b.label and a.full_name != b.full_name
    assert "head offsets" in b.full_name and "tip offsets" in a.full_name


def test_runs_whose_force_was_learnt_unturned_are_told_apart_and_read_back() -> None:
    """``--no-rotate-force`` is its own variant (never pooled with the recipe's), written as
    ``rotate_force: false`` (1.6) and read back; every other variant's row is as before."""
    still = Variant("cGNN", "Exp", True, False, None, Offsets.HEADS, rotate_force=False)
    turned = Variant("cGNN", "Exp", True, False, None, Offsets.HEADS)
    assert still != turned and hash(still) != hash(turned)
    assert still.to_dict()["rotate_force"] is False and "rotate_force" not in turned.to_dict()
    assert Variant.from_dict(still.to_dict()) == still
    assert "force unturned" in still.full_name and "force unturned" not in turned.full_name
    made = make_variant(CGNNConfig(), TrainOptions(rotate=True, rotate_force=False), "x.h5",
                        None)
    assert made == replace(made, rotate_force=False) != replace(made, rotate_force=True)


def test_a_variant_is_written_as_the_documents_row_and_read_back() -> None:
    """A variant's plain form is ``metrics.json``'s row (the keys and order every document
    has kept), reads back equal, and the document's offsets are :class:`Offsets`' values."""
    tuned = Variant("cGNN", "Exp", True, False, Variant("cGNN", "MSM", True, True),
                    Offsets.HEADS)
    plain = tuned.to_dict()
    assert plain == {"model": "cGNN", "train_data": "Exp", "rotate": True, "aug": False,
                     "pretrained": {"model": "cGNN", "train_data": "MSM", "rotate": True,
                                    "aug": True, "pretrained": None, "offsets": "none"},
                     "offsets": "heads"}
    assert list(plain) == ["model", "train_data", "rotate", "aug", "pretrained", "offsets"]
    assert Variant.from_dict(plain) == tuned
    assert OFFSETS == tuple(o.value for o in Offsets)

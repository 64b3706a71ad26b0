"""Checkpoints of earlier versions read in today's form (:mod:`train.training.migrate`): each
numbered case of its docstring on a hand-built old dict, and end to end a checkpoint rewritten
into an old form that loads and predicts as the original does.

Known truth: what each old field meant (``tip_offsets`` True: the first layer read the
offsets; ``head_offsets`` n: the heads read n numbers of them; neither: the paper's network),
written out here by hand, never taken from the migration's output.
"""

from __future__ import annotations

import copy
import warnings
from pathlib import Path

import h5py
import numpy as np
import pytest
import torch

from core.errors import BadInput
from train.inference.predictor import Predictor
from train.model.cgnn import CGNN
from train.model.config import OFFSET_WIDTH, CGNNConfig
from train.model.normalise import Envelope, Normaliser
from train.training.checkpoint import load_checkpoint
from train.training.migrate import migrate
from train.training.train_params import TrainOptions
from train.training.variant import Variant

WIDTHS = {"edge_widths": ((8, 8),) * 3, "disp_widths": (16,), "force_widths": (8, 8, 8)}
ENVELOPE = Envelope(1e-3, 5e-3, -4e-3, 8e-3, -1.0, 3.0, 0.5e-3)
NORM = Normaliser((0.05, 0.05, 0.0), 0.03, 0.002, 0.5, 0.08, ENVELOPE)


def _old_config(**old: object) -> dict:
    """A small network's config as written before ``offsets``: today's widths, no
    ``offsets``/``offset_width``, and the old fields ``old``."""
    d = CGNNConfig(**WIDTHS).to_dict()
    del d["offsets"], d["offset_width"]
    return {**d, **old}


# --- case 1: where the network reads the offsets --------------------------------------------

@pytest.mark.parametrize(("old", "offsets", "width"), [
    ({"tip_offsets": True, "head_offsets": 0}, "graph", OFFSET_WIDTH),
    ({"tip_offsets": True}, "graph", OFFSET_WIDTH),
    ({"tip_offsets": False, "head_offsets": 32}, "heads", 32),
    ({"tip_offsets": False, "head_offsets": 12}, "heads", 12),
    ({"tip_offsets": False, "head_offsets": 0}, "none", OFFSET_WIDTH),
    ({"tip_offsets": False}, "none", OFFSET_WIDTH),
    ({}, "none", OFFSET_WIDTH),
])
def test_old_offset_fields_become_one_offsets_setting(old: dict, offsets: str, width: int
                                                      ) -> None:
    """In ``config`` and in ``meta.config`` alike; the old fields are gone, the rest kept, and
    the result is a config today's reader accepts."""
    state = {"config": _old_config(**old), "meta": {"config": _old_config(**old)}}
    out = migrate(state)
    want = CGNNConfig(**WIDTHS, offsets=offsets, offset_width=width)
    for config in (out["config"], out["meta"]["config"]):
        assert "tip_offsets" not in config and "head_offsets" not in config
        assert config["offsets"] == offsets and config["offset_width"] == width
        assert CGNNConfig.from_dict(config) == want


def test_a_current_config_is_left_as_it_is() -> None:
    """Today's form, with a width other than the default: nothing is changed."""
    config = CGNNConfig(**WIDTHS, offsets="heads", offset_width=7).to_dict()
    out = migrate({"config": copy.deepcopy(config)})
    assert out["config"] == config


# --- case 2: the encoder's weights' name ----------------------------------------------------

def test_the_old_encoder_weights_are_renamed_in_model_and_trained() -> None:
    """``offsets.weight``/``offsets.bias`` become ``encoder.*`` (the same tensors); a name
    with ``offsets.`` elsewhere than at its start, and every other weight, keep theirs."""
    w, b, other, inner = torch.ones(4, 8), torch.zeros(4), torch.full((3,), 2.0), torch.ones(2)
    for key in ("model", "trained"):
        old = {"offsets.weight": w, "offsets.bias": b, "convs.0.mlp.0.weight": other,
               "disp_head.offsets.weight": inner}
        out = migrate({key: old})[key]
        assert set(out) == {"encoder.weight", "encoder.bias", "convs.0.mlp.0.weight",
                            "disp_head.offsets.weight"}
        assert out["encoder.weight"] is w and out["encoder.bias"] is b
        assert out["convs.0.mlp.0.weight"] is other and out["disp_head.offsets.weight"] is inner


# --- case 3: the normaliser's envelope ------------------------------------------------------

def test_a_normaliser_without_an_envelope_or_its_top_gets_them_as_unknown() -> None:
    """No envelope: None; an envelope without ``top``: its fields kept, ``top`` None; a current
    normaliser unchanged."""
    full = NORM.to_dict()
    bare = {k: v for k, v in full.items() if k != "envelope"}
    assert migrate({"norm": bare})["norm"] == {**bare, "envelope": None}
    no_top = copy.deepcopy(full)
    del no_top["envelope"]["top"]
    env = migrate({"norm": no_top})["norm"]["envelope"]
    assert env == {"press_min": 1e-3, "press_max": 5e-3, "tip_lowest": -4e-3,
                   "gap_max": 8e-3, "force_min": -1.0, "force_max": 3.0, "top": None}
    assert Normaliser.from_dict(migrate({"norm": copy.deepcopy(full)})["norm"]) == NORM


# --- case 4: training options added later ---------------------------------------------------

def test_options_added_later_get_the_default_they_trained_with() -> None:
    """A run of an older version recorded fold, epochs, lr and seed only: the others are
    TrainOptions' defaults (what it ran with), the recorded ones are kept."""
    recorded = {"fold": 1, "epochs": 40, "lr": 3e-3, "seed": 9}
    out = migrate({"meta": {"config": _old_config(), "options": dict(recorded)}})
    options = out["meta"]["options"]
    defaults = TrainOptions().to_dict()
    assert set(options) == set(defaults)
    for name, value in defaults.items():
        assert options[name] == recorded.get(name, value), name
    assert TrainOptions(**options) == TrainOptions(fold=1, epochs=40, lr=3e-3, seed=9)


# --- case 5: variants without offsets -------------------------------------------------------

def _variant(**kw: object) -> dict:
    """A variant's plain form as recorded before ``offsets``."""
    return {"model": "cGNN", "train_data": "Exp", "rotate": False, "aug": False,
            "pretrained": None, **kw}


def test_a_variant_without_offsets_gets_its_network_s_and_its_pretrained_the_run_s() -> None:
    """A fine-tuned run with head offsets (width 16, old config): its variant and the one
    it was fine-tuned from (the same network) both read "heads"."""
    meta = {"config": _old_config(tip_offsets=False, head_offsets=16), "options": {"fold": 0},
            "variant": _variant(rotate=True, pretrained=_variant(train_data="MSM", aug=True))}
    v = migrate({"meta": meta})["meta"]["variant"]
    assert v == {"model": "cGNN", "train_data": "Exp", "rotate": True, "aug": False,
                 "offsets": "heads",
                 "pretrained": {"model": "cGNN", "train_data": "MSM", "rotate": False,
                                "aug": True, "pretrained": None, "offsets": "heads"}}
    assert Variant.from_dict(v).pretrained.offsets == "heads"


def test_offsets_a_variant_records_are_kept() -> None:
    """A variant that says where it reads offsets keeps it, and passes its own down to a
    pretrained one lacking them (not the config's)."""
    meta = {"config": _old_config(tip_offsets=True), "options": {"fold": 0},
            "variant": _variant(offsets="none", pretrained=_variant())}
    v = migrate({"meta": meta})["meta"]["variant"]
    assert v["offsets"] == "none" and v["pretrained"]["offsets"] == "none"


# --- case 6: no variant at all --------------------------------------------------------------

def _states(path: Path, source: str) -> Path:
    """A file that says where its states came from (all the variant reads of it)."""
    with h5py.File(path, "w") as f:
        f.attrs["source"] = source
    return path


def _old_meta(data: Path, init: Path | None, **options: object) -> dict:
    """A run's meta from before variants were recorded (and before ``offsets``)."""
    return {"config": _old_config(tip_offsets=False), "options": {"fold": 0, **options},
            "data": {"file": str(data), "sha256": "0" * 64}, "splits": "s.json",
            "init": None if init is None else str(init)}


def test_a_meta_without_a_variant_gets_the_one_its_run_describes(tmp_path: Path) -> None:
    """Rotation, a point fraction (aug), lab data (Exp), trained from scratch, the paper's
    network."""
    data = _states(tmp_path / "lab.h5", "lab")
    meta = migrate({"meta": _old_meta(data, None, rotate=True, point_fraction=0.5)})["meta"]
    assert meta["variant"] == {"model": "cGNN", "train_data": "Exp", "rotate": True,
                               "aug": True, "pretrained": None, "offsets": "none"}


def test_a_fine_tuned_run_without_a_variant_reads_its_init_checkpoint(tmp_path: Path) -> None:
    """Its --init checkpoint (itself from before variants: MSM data, aug) gives the variant it
    was fine-tuned from; the run's own is its own (Exp, no aug)."""
    msm, lab = _states(tmp_path / "msm.h5", "msm"), _states(tmp_path / "lab.h5", "lab")
    init = tmp_path / "pre.pt"
    torch.save({"meta": _old_meta(msm, None, point_fraction=0.2)}, init)
    meta = migrate({"meta": _old_meta(lab, init)})["meta"]
    assert meta["variant"] == {
        "model": "cGNN", "train_data": "Exp", "rotate": False, "aug": False, "offsets": "none",
        "pretrained": {"model": "cGNN", "train_data": "MSM", "rotate": False, "aug": True,
                       "pretrained": None, "offsets": "none"}}


def test_a_missing_init_checkpoint_is_bad_input_naming_it(tmp_path: Path) -> None:
    """A run from before variants whose --init checkpoint has gone: its variant cannot be known,
    said naming the file."""
    gone = tmp_path / "moved.pt"
    with pytest.raises(BadInput) as e:
        migrate({"meta": _old_meta(_states(tmp_path / "lab.h5", "lab"), gone)})
    assert e.value.path == str(gone)
    assert "cannot be read, so its variant is unknown" in e.value.what
    assert "\n" not in e.value.what


def test_what_is_not_a_checkpoint_is_left_for_the_checks() -> None:
    """Not a dict, or a dict lacking what a case reads: returned as it is."""
    assert migrate([1, 2]) == [1, 2]
    assert migrate({}) == {}
    odd = {"config": "x", "model": [1], "norm": None, "meta": {"options": {}}}
    assert migrate(copy.deepcopy(odd)) == odd


# --- end to end: an old checkpoint loads and predicts as the original -----------------------

NETWORKS = {"paper": ({}, {"tip_offsets": False}),
            "tip offsets": ({"offsets": "graph"}, {"tip_offsets": True}),
            "head offsets": ({"offsets": "heads", "offset_width": 4},
                             {"tip_offsets": False, "head_offsets": 4})}


def _checkpoint(config: CGNNConfig) -> dict:
    """Today's checkpoint of a seeded small network (as the train runner writes one)."""
    torch.manual_seed(0)
    options = TrainOptions(epochs=2).to_dict()
    return {"model": CGNN(config).state_dict(), "epoch": 1, "best_val": 0.5,
            "config": config.to_dict(), "norm": NORM.to_dict(),
            "meta": {"options": options, "config": config.to_dict(),
                     "data": {"file": "/data/states.h5", "sha256": "0" * 64},
                     "splits": "/data/splits.json", "init": None,
                     "variant": Variant("cGNN", "Exp", False, False,
                                        offsets=config.offsets).to_dict()}}


def _as_old(state: dict, old_fields: dict) -> dict:
    """``state`` as an old version wrote it: the old config fields, the encoder under its old
    name, no envelope top, a variant without offsets, options without those added later."""
    old = copy.deepcopy(state)
    for config in (old["config"], old["meta"]["config"]):
        del config["offsets"], config["offset_width"]
        config.update(old_fields)
    old["model"] = {k.replace("encoder.", "offsets.", 1) if k.startswith("encoder.") else k: v
                    for k, v in old["model"].items()}
    del old["norm"]["envelope"]["top"]
    del old["meta"]["variant"]["offsets"]
    for name in ("ema", "no_val", "patience", "schedule", "loss"):
        del old["meta"]["options"][name]
    return old


@pytest.mark.parametrize("network", list(NETWORKS))
def test_an_old_checkpoint_loads_and_predicts_as_the_original(tmp_path: Path, network: str
                                                              ) -> None:
    """Each network rewritten in its old form loads as today's (config, meta, weights) and the
    predictor answers as the original's within 1e-6 (a press and a still tip)."""
    new_kw, old_fields = NETWORKS[network]
    state = _checkpoint(CGNNConfig(**WIDTHS, **new_kw))
    torch.save(state, tmp_path / "new.pt")
    torch.save(_as_old(state, old_fields), tmp_path / "old.pt")
    if network == "head offsets":
        assert any(k.startswith("offsets.") for k in _as_old(state, old_fields)["model"])
    loaded = load_checkpoint(tmp_path / "old.pt")
    assert loaded["config"] == state["config"] and loaded["meta"] == state["meta"]
    for name, w in state["model"].items():
        assert torch.equal(loaded["model"][name], w), name
    rng = np.random.default_rng(0)
    points = np.c_[rng.uniform(0, 0.1, (30, 2)), np.zeros(30)].astype(np.float32)
    press = np.array([0.05, 0.05, 0.001, 0.052, 0.05, -0.002], np.float32)
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")       # an untrained net's force may leave the range
        new = Predictor.load(tmp_path / "new.pt", backend="torch")
        old = Predictor.load(tmp_path / "old.pt", backend="torch")
        for p in (press, press[[0, 1, 2, 0, 1, 2]]):
            (d_new, f_new), (d_old, f_old) = new.predict(points, p), old.predict(points, p)
            np.testing.assert_allclose(d_old, d_new, atol=1e-6, rtol=0)
            assert f_old == pytest.approx(f_new, abs=1e-6)
            assert old.predict_force(points, p) == pytest.approx(f_new, abs=1e-6)

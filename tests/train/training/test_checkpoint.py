"""Checkpoints (:mod:`train.training.checkpoint`): a dict built here, saved and loaded, is read
back whole, and each way a dict is not a checkpoint of ours is refused in one line naming the
file and what is wrong, before anything of it is used.

``tests/train/training/test_train_bad_inputs.py`` damages a trained run's checkpoint through
``pipeline train --init`` (refused or the same run); here the checks are called directly on
hand-built dicts, each named for the key it reads.
"""

from __future__ import annotations

from pathlib import Path

import pytest
import torch
from helpers.cgnn_data import TINY

from core.errors import BadInput
from train.model.cgnn import CGNN
from train.model.config import CGNNConfig
from train.model.normalise import Envelope, Normaliser
from train.training.checkpoint import check_checkpoint, load_checkpoint, model_from
from train.training.train_params import TrainOptions
from train.training.variant import Variant

NORM = Normaliser((0.05, 0.05, 0.0), 0.03, disp_scale=0.002, force_scale=0.5, extent=0.08,
                  envelope=Envelope(1e-3, 5e-3, -4e-3, 8e-3, -1.0, 3.0, 0.5e-3))


def _state(config: CGNNConfig = TINY, seed: int = 0) -> dict:
    """A checkpoint as the train runner writes one: a seeded small network's weights, its
    config, the normaliser, and the run's meta."""
    torch.manual_seed(seed)
    model = CGNN(config)
    return {"model": model.state_dict(), "optimizer": {"state": {}, "param_groups": []},
            "epoch": 3, "best_val": 0.25, "best_epoch": 2, "config": config.to_dict(),
            "norm": NORM.to_dict(),
            "meta": {"options": TrainOptions(epochs=4).to_dict(), "config": config.to_dict(),
                     "data": {"file": "/data/states.h5", "sha256": "ab" * 32,
                              "point_names": ["P0", "P1"]},
                     "splits": "/data/splits.json", "init": None,
                     "variant": Variant("cGNN", "Exp", False, False).to_dict()}}


def _refused(path: Path | str, state: object, *words: str) -> str:
    """``check_checkpoint`` refuses ``state``: one line naming ``path`` and ``words``."""
    with pytest.raises(BadInput) as e:
        check_checkpoint(path, state)
    line = str(e.value)
    assert line.startswith(f"{path}: ") and "\n" not in e.value.what, line
    for w in words:
        assert w in line, line
    return line


def test_a_saved_checkpoint_loads_back_whole(tmp_path: Path) -> None:
    """torch.save then load_checkpoint: it passes the checks and every part is what was
    saved: the weights bit for bit, the config, the normaliser with its envelope, the meta;
    the model it makes answers as the saved network did."""
    state = _state()
    path = tmp_path / "best.pt"
    torch.save(state, path)
    loaded = load_checkpoint(path)
    check_checkpoint(path, loaded)
    assert set(loaded["model"]) == set(state["model"])
    for name, w in state["model"].items():
        assert torch.equal(loaded["model"][name], w), name
    assert CGNNConfig.from_dict(loaded["config"]) == TINY
    assert Normaliser.from_dict(loaded["norm"]) == NORM
    assert loaded["meta"] == state["meta"]
    assert (loaded["epoch"], loaded["best_val"]) == (3, 0.25)
    model, norm = model_from(loaded)
    torch.manual_seed(0)
    reference = CGNN(TINY).eval()
    x, c = torch.rand(1, 20, 3) * 0.1, torch.rand(1, 6) * 0.1
    with torch.no_grad():
        for got, want in zip(model(x, c), reference(x, c), strict=True):
            assert torch.equal(got, want)
    assert not model.training and norm == NORM


def test_a_checkpoint_of_an_averaging_run_checks_its_trained_weights_too() -> None:
    """With --ema the stepped weights ("trained") travel beside the average: they are the
    network's too, and finite."""
    state = _state()
    state["trained"] = _state(seed=1)["model"]
    check_checkpoint("ema.pt", state)
    name = next(iter(state["trained"]))
    state["trained"][name] = state["trained"][name] * float("nan")
    _refused("ema.pt", state, f"weight {name} is not finite")


@pytest.mark.parametrize("value", [[1, 2], "model", None, (1,)])
def test_anything_but_a_dict_is_refused_naming_its_type(value: object) -> None:
    """A list, text, None or tuple is no checkpoint: its type is named."""
    _refused("x.pt", value, "not a checkpoint of `pipeline train`",
             f"holds a {type(value).__name__}, not a dict")


@pytest.mark.parametrize("key", ["model", "config", "norm", "meta"])
def test_a_missing_key_is_named(key: str) -> None:
    """Each key inference needs, missing, is named."""
    state = _state()
    del state[key]
    _refused("x.pt", state, f"lacks ['{key}']")


def test_weights_of_another_width_name_the_weight_and_both_shapes() -> None:
    """The 8-wide network's weights under a 12-wide config: same names, other shapes."""
    state = _state()
    wider = CGNNConfig(edge_widths=((12, 12),) * 3, disp_widths=(16,), force_widths=(8, 8, 8))
    state["config"] = wider.to_dict()
    with torch.device("meta"):
        want = {k: tuple(v.shape) for k, v in CGNN(wider).state_dict().items()}
    first = next(k for k, v in state["model"].items() if tuple(v.shape) != want[k])
    _refused("x.pt", state, f"weight {first} is {tuple(state['model'][first].shape)}",
             f"its config needs {want[first]}")


def test_weights_of_another_network_name_the_odd_keys() -> None:
    """The paper's network's weights under a config with head offsets: the encoder's weights
    are missing (and its heads' first layers wider)."""
    state = _state()
    state["config"] = CGNNConfig(edge_widths=((8, 8),) * 3, disp_widths=(16,),
                                 force_widths=(8, 8, 8), offsets="heads",
                                 offset_width=4).to_dict()
    _refused("x.pt", state, "model weights do not match its config",
             "'encoder.bias', 'encoder.weight'")


def test_a_nan_weight_is_named() -> None:
    """A NaN weight is refused before any prediction can spread it."""
    state = _state()
    name = list(state["model"])[-1]
    state["model"][name][0] = float("nan")
    _refused("x.pt", state, f"weight {name} is not finite")


def test_a_normaliser_in_millimetres_is_refused_asking_about_millimetres() -> None:
    """Every length of the normaliser 1000 times too large (written in mm): the centre is
    50 m out along x, beyond any phantom; with the centre right, the scale (30 m) is next."""
    state = _state()
    mm = {**NORM.to_dict(), "centre": [1e3 * v for v in NORM.centre], "scale": 30.0,
          "disp_scale": 2.0, "extent": 80.0}
    state["norm"] = mm
    _refused("x.pt", state, "norm.centre is 50 m", "millimetres?")
    mm["centre"] = list(NORM.centre)
    _refused("x.pt", state, "norm.scale is 30 m", "millimetres?")


def test_a_normaliser_missing_a_field_is_not_usable() -> None:
    """A normaliser lacking a scale is not usable, said with the parser's error."""
    state = _state()
    del state["norm"]["disp_scale"]
    _refused("x.pt", state, "checkpoint key 'norm' is not usable", "KeyError")


def test_meta_without_the_data_file_is_refused() -> None:
    """The run's data file is what evaluation and resumption read: it must be named."""
    state = _state()
    del state["meta"]["data"]["file"]
    _refused("x.pt", state, "meta lacks data.file or options.fold")


@pytest.mark.parametrize(("key", "value"), [("init", 7), ("data", "states.h5"),
                                            ("options", None)])
def test_meta_of_the_wrong_type_is_refused(key: str, value: object) -> None:
    """Each meta field of the wrong type is named."""
    state = _state()
    state["meta"][key] = value
    _refused("x.pt", state, f"meta.{key} is missing or not of type")


def test_a_meta_that_is_no_dict_is_refused() -> None:
    """A meta that is not a dict is refused before its fields are read."""
    state = _state()
    state["meta"] = ["options"]
    _refused("x.pt", state, "checkpoint key 'meta' is not a dict")


class _Call:
    """A pickle that runs code on load (``print``) if anything unpickles it unsafely."""

    def __reduce__(self):
        return (print, ("code ran while loading a checkpoint",))


def test_a_pickle_with_code_is_refused_naming_what_it_would_run_and_never_runs_it(
        tmp_path: Path, capsys: pytest.CaptureFixture) -> None:
    """A checkpoint hiding a call (print) in its meta: refused, naming the call, and the call is
    never made (nothing printed)."""
    path = tmp_path / "evil.pt"
    state = _state()
    state["meta"]["notes"] = [_Call()]
    torch.save(state, path)
    with pytest.raises(BadInput) as e:
        load_checkpoint(path)
    line = str(e.value)
    assert line.startswith(f"{path}: ") and "\n" not in e.value.what, line
    assert "holds pickled code (print)" in line and "not run" in line, line
    assert "code ran" not in capsys.readouterr().out


def test_a_missing_file_is_named(tmp_path: Path) -> None:
    """A missing checkpoint: one line naming it."""
    with pytest.raises(BadInput) as e:
        load_checkpoint(tmp_path / "gone.pt")
    assert str(e.value) == f"{tmp_path / 'gone.pt'}: no such checkpoint"


@pytest.mark.parametrize("field", ["press_min", "press_max", "force_max"])
def test_an_envelope_missing_a_field_it_always_had_is_refused(tmp_path: Path, field: str
                                                              ) -> None:
    """Only ``top`` was added to the envelope later (migration case 3); an envelope lacking
    any other field is damaged, and must be refused on load, naming it, rather than loaded
    with the field None (the predictor then fails with a TypeError on its first press:
    ``None * float`` in ``press_gate`` / the envelope check, exit 1, not one line)."""
    state = _state()
    del state["norm"]["envelope"][field]
    path = tmp_path / "damaged.pt"
    torch.save(state, path)
    with pytest.raises(BadInput) as e:
        load_checkpoint(path)
    assert str(e.value).startswith(f"{path}: ") and field in e.value.what

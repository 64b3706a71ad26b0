"""The training loop's parts (:mod:`train.training.loop`) against hand numbers: the step
size's schedule, the optimizer and the weights' average, each epoch's seeded draws, the stall
warning, the options' guard, early stopping and the best epoch, what a run's checkpoints
record of it, the validation metrics, and what a run's checkpoint holds. When the files are
written: ``test_run_files.py``.

Whole runs (learning, resuming, a resumed run of other options refused, patience, ema) are
``tests/train/training/test_train_stage.py``'s; runs that cannot learn are
``test_train_extremes.py``'s.
"""

from __future__ import annotations

import math
from dataclasses import asdict
from pathlib import Path
from types import SimpleNamespace

import numpy as np
import pytest
import torch
from helpers.cgnn_data import DENT_NAMES, TINY
from torch import nn

from core.errors import BadInput
from train.data import StateTensors
from train.model.config import CGNNConfig
from train.model.normalise import Envelope, Normaliser
from train.training.loop import (
    STALL_PROBE,
    STALL_REL,
    _track_best,
    adam,
    checkpoint_state,
    evaluate_pairs,
    learning_rate,
    resolve_device,
    run_meta,
    run_notes,
    seeded,
    stalled,
    stopped_early,
    turned,
    update_average,
)
from train.training.run_files import RunFiles
from train.training.train_params import TrainOptions

# --- the step size ---------------------------------------------------------------------------

def test_a_constant_schedule_keeps_the_rate() -> None:
    """The constant schedule: lr at every epoch."""
    opts = TrainOptions(epochs=7, lr=2e-3, schedule="constant")
    assert [learning_rate(opts, e) for e in range(7)] == [2e-3] * 7


def test_the_cosine_falls_from_lr_to_a_hundredth_at_the_last_epoch() -> None:
    """lr (0.01 + 0.99 (1 + cos(pi t)) / 2), t = epoch / (epochs - 1): at a quarter
    (epoch 2 of 9) 1e-3 (0.01 + 0.99 (1 + 1/sqrt 2) / 2) = 0.855018e-3; falling each epoch."""
    opts = TrainOptions(epochs=9, lr=1e-3, schedule="cosine")
    rates = [learning_rate(opts, e) for e in range(9)]
    assert rates[0] == pytest.approx(1e-3, rel=1e-12)
    assert rates[-1] == pytest.approx(1e-5, rel=1e-9)
    assert rates[2] == pytest.approx(1e-3 * (0.01 + 0.99 * (1 + 2**-0.5) / 2), rel=1e-12)
    assert rates[2] == pytest.approx(0.855018e-3, rel=1e-6)
    assert rates[6] == pytest.approx(1e-3 * (0.01 + 0.99 * (1 - 2**-0.5) / 2), rel=1e-12)
    assert all(a > b for a, b in zip(rates[:-1], rates[1:], strict=True))


def test_a_one_epoch_cosine_is_the_rate_itself() -> None:
    """No last epoch to fall to (and no division by epochs - 1 = 0)."""
    assert learning_rate(TrainOptions(epochs=1, lr=5e-4, schedule="cosine"), 0) == 5e-4


# --- the optimizer and the weights' average --------------------------------------------------

def test_the_trainers_adam_is_adams_update() -> None:
    """Three steps of the trainer's (fused) Adam against Adam's update written out (Kingma &
    Ba, bias-corrected, eps 1e-8), on fixed gradients of a weight and a bias."""
    layer = nn.Linear(3, 2)
    start = [p.detach().double().clone() for p in layer.parameters()]
    grads = [[torch.full_like(p, 0.5 * (s + 1)) * (-1) ** i for i, p in
              enumerate(layer.parameters())] for s in range(3)]
    opt, lr = adam(layer.parameters(), 1e-2), 1e-2
    for g in grads:
        for p, gp in zip(layer.parameters(), g, strict=True):
            p.grad = gp.clone()
        opt.step()
    for i, (p, w) in enumerate(zip(layer.parameters(), start, strict=True)):
        m = v = torch.zeros_like(w)
        for t, g in enumerate(grads, start=1):
            gd = g[i].double()
            m, v = 0.9 * m + 0.1 * gd, 0.999 * v + 0.001 * gd * gd
            w = w - lr * (m / (1 - 0.9 ** t)) / ((v / (1 - 0.999 ** t)).sqrt() + 1e-8)
        assert torch.allclose(p.detach().double(), w, atol=1e-6)


def test_the_average_moves_a_hundredth_of_the_way_to_the_weights() -> None:
    """avg <- 0.99 avg + 0.01 w, for every parameter (decay 0.99)."""
    model, avg = nn.Linear(2, 2), nn.Linear(2, 2)
    before = [a.detach().clone() for a in avg.parameters()]
    update_average(SimpleNamespace(model=model, averaged=avg), 0.99)
    for a, b, w in zip(avg.parameters(), before, model.parameters(), strict=True):
        assert torch.allclose(a, 0.99 * b + 0.01 * w.detach(), atol=1e-7)


# --- each epoch's draws ----------------------------------------------------------------------

def _draws(g: torch.Generator) -> tuple[torch.Tensor, torch.Tensor]:
    """What an epoch draws: a shuffle, then points and angles."""
    return torch.randperm(50, generator=g), torch.rand(8, generator=g)


def test_the_same_seed_and_epoch_draw_the_same_whatever_came_before() -> None:
    """A resumed run's epoch draws what the uninterrupted run's did: the generator depends
    on (seed, epoch) alone, not on the global RNG or earlier epochs."""
    first = _draws(seeded(3, 5))
    torch.manual_seed(12345)
    torch.rand(100)
    _draws(seeded(3, 4))
    again = _draws(seeded(3, 5))
    for a, b in zip(first, again, strict=True):
        assert torch.equal(a, b)
    assert seeded(3, 5).device == torch.device("cpu")


@pytest.mark.parametrize(("seed", "epoch"), [(3, 6), (4, 5), (0, 0)])
def test_another_epoch_or_seed_draws_otherwise(seed: int, epoch: int) -> None:
    """Each epoch and seed its own shuffle: not the same order again and again."""
    perm, _ = _draws(seeded(3, 5))
    other, _ = _draws(seeded(seed, epoch))
    assert not torch.equal(perm, other)
    assert sorted(other.tolist()) == list(range(50))       # still a shuffle


def test_without_rotate_force_only_unturned_examples_teach_the_force() -> None:
    """About half the examples stay unturned (the identity), each weighing 2 on the force so
    the term keeps its scale; every turned one weighs 0. With the force turned too, or no
    rotation, nothing is weighed."""
    turns, weight = turned(4000, TrainOptions(rotate=True, rotate_force=False), seeded(0, 0))
    assert turns is not None and weight is not None
    still = torch.linalg.matrix_norm(turns - torch.eye(3)) < 1e-12
    assert torch.equal(weight > 0, still)
    assert set(weight.tolist()) == {0.0, 2.0}
    assert float(weight.mean()) == pytest.approx(1.0, abs=0.1)     # sd of the mean 0.016
    every, none = turned(10, TrainOptions(rotate=True), seeded(0, 0))
    assert none is None and every is not None and bool(
        (torch.linalg.matrix_norm(every - torch.eye(3)) > 1e-6).all())
    assert turned(10, TrainOptions(), seeded(0, 0)) == (None, None)


# --- a loss that does not move ---------------------------------------------------------------

def test_a_loss_that_moves_less_than_stall_rel_is_a_warning() -> None:
    """1.0 -> 0.99996: a relative change of 4e-5 < 1e-4; the message names both losses, the
    probe's size, the epochs and what to do."""
    assert STALL_REL == 1e-4
    text = stalled(1.0, 0.99996, 3)
    assert text is not None
    assert "1 -> 0.99996" in text and f"on {STALL_PROBE} training examples" in text
    assert "over the first 3 epoch(s)" in text and "4e-05 < 0.0001" in text
    assert "--lr" in text
    assert stalled(2.0, 2.00004, 1) is not None               # up as much: the same
    assert stalled(0.0, 0.0, 1) is not None                  # nothing at all: stalled


@pytest.mark.parametrize(("before", "after"), [(1.0, 0.9997), (1.0, 0.5), (2.0, 2.001),
                                               (1e-6, 0.5e-6), (0.0, 1e-12)])
def test_a_loss_that_moves_is_no_warning(before: float, after: float) -> None:
    """A relative change of STALL_REL or more (either way), or any from 0: no warning."""
    assert stalled(before, after, 3) is None


# --- the options' guard ----------------------------------------------------------------------

@pytest.mark.parametrize("field", ["lr", "alpha", "ema", "point_fraction"])
@pytest.mark.parametrize("value", [-0.1, 0.0, math.inf, -math.inf, math.nan])
def test_a_non_positive_or_infinite_rate_or_weight_is_refused_naming_it(field: str,
                                                                       value: float) -> None:
    """The options refuse it as they are made, so it never reaches the optimizer."""
    with pytest.raises(BadInput) as e:
        TrainOptions(**{field: value})
    assert e.value.path is None
    assert str(e.value).startswith(f"{field} {value}")


def test_unset_optional_weights_and_the_paper_s_options_pass() -> None:
    """The defaults, no average and no point fraction (None), and usual values pass."""
    TrainOptions()
    TrainOptions(ema=None, point_fraction=None, loss="balanced")
    TrainOptions(ema=0.99, point_fraction=0.3, lr=2e-3, alpha=1.0)


@pytest.mark.parametrize("loss", ["l1", "Paper", ""])
def test_an_unknown_loss_is_refused_naming_the_known(loss: str) -> None:
    """A loss must be one of Loss's values, exactly (case included)."""
    with pytest.raises(BadInput) as e:
        TrainOptions(loss=loss)
    assert str(e.value) == f"loss {loss!r}: must be one of paper, balanced"


# --- early stopping and the best epoch -------------------------------------------------------

@pytest.mark.parametrize(("patience", "best", "epoch", "stop"), [
    (None, 0, 100, False),     # no patience: never
    (2, -1, 10, False),        # nothing validated yet
    (2, 3, 5, False),          # two epochs without better: still going
    (2, 3, 6, True),           # three: stop
    (1, 4, 6, True),           # patience 1: the second epoch without better
    (1, 4, 5, False),
])
def test_a_run_stops_once_patience_epochs_pass_without_a_better_loss(
        patience: int | None, best: int, epoch: int, stop: bool) -> None:
    """Stop when more than ``patience`` epochs passed since the best; never without patience or a
    best."""
    run = SimpleNamespace(best_epoch=best)
    assert stopped_early(run, TrainOptions(patience=patience), epoch) is stop


def test_the_best_epoch_is_the_first_lowest_validation_loss() -> None:
    """Losses 3, 2, 2.5, 1, 1, 4: the best is epoch 3 (a tie keeps the earlier), loss 1."""
    run = SimpleNamespace(best_val=math.inf, best_epoch=-1)
    seen = []
    for epoch, loss in enumerate([3.0, 2.0, 2.5, 1.0, 1.0, 4.0]):
        _track_best(run, epoch, loss)
        seen.append((run.best_epoch, run.best_val))
    assert seen == [(0, 3.0), (1, 2.0), (1, 2.0), (3, 1.0), (3, 1.0), (3, 1.0)]


def test_a_nan_first_validation_still_gives_a_best_epoch_and_a_real_loss_beats_it() -> None:
    """A NaN validation loss never becomes the best value, but the first epoch is kept until a real
    loss comes."""
    run = SimpleNamespace(best_val=math.inf, best_epoch=-1)
    _track_best(run, 0, math.nan)
    assert run.best_epoch == 0 and run.best_val == math.inf
    _track_best(run, 1, 5.0)
    assert (run.best_epoch, run.best_val) == (1, 5.0)


def test_without_validation_the_last_epoch_is_the_best() -> None:
    """--no-val: every epoch replaces the best (best.pt is the last epoch)."""
    run = SimpleNamespace(best_val=1.0, best_epoch=0)
    for epoch in (1, 2):
        _track_best(run, epoch, math.nan, last=True)
        assert run.best_epoch == epoch and math.isnan(run.best_val)


# --- what a run's checkpoints record of it ---------------------------------------------------

def test_run_meta_records_resolved_paths_options_network_and_variant(
        dent: tuple[Path, Path], tmp_path: Path, monkeypatch: pytest.MonkeyPatch) -> None:
    """Given relative paths (from the data's folder), the meta names the files absolutely;
    the options and network as plain dicts; the data's point names; the variant from the
    options (rotation, a point fraction: aug), the file's source (lab: Exp) and the network
    (head offsets)."""
    data, splits = dent
    monkeypatch.chdir(data.parent)
    opts = TrainOptions(fold=1, rotate=True, point_fraction=0.5, seed=7)
    config = CGNNConfig(edge_widths=((8, 8),) * 3, disp_widths=(16,), force_widths=(8, 8, 8),
                        offsets="heads", offset_width=4)
    meta = run_meta(Path(data.name), Path(splits.name), None, opts, config, "ab" * 32, None)
    assert meta["data"] == {"file": str(data.resolve()), "sha256": "ab" * 32,
                            "point_names": DENT_NAMES}
    assert meta["splits"] == str(splits.resolve()) and meta["init"] is None
    assert meta["options"] == asdict(opts) and meta["options"]["fold"] == 1
    assert {type(meta["options"][k]) for k in ("loss", "schedule")} == {str}   # plain text
    assert meta["config"] == config.to_dict() and meta["config"]["offsets"] == "heads"
    assert meta["variant"] == {"model": "cGNN", "train_data": "Exp", "rotate": True,
                               "aug": True, "pretrained": None, "offsets": "heads"}


def test_run_meta_of_a_fine_tuned_run_names_its_init_and_the_variant_it_came_from(
        dent: tuple[Path, Path], tmp_path: Path, monkeypatch: pytest.MonkeyPatch) -> None:
    """A relative --init is named absolutely, and its checkpoint's variant is the pretrained one."""
    data, splits = dent
    monkeypatch.chdir(tmp_path)
    pre = {"model": "cGNN", "train_data": "MSM", "rotate": False, "aug": True,
           "pretrained": None, "offsets": "none"}
    init = Path("pre.pt")
    meta = run_meta(data, splits, init, TrainOptions(), TINY, "0" * 64,
                    {"meta": {"variant": pre}})
    assert meta["init"] == str(tmp_path.resolve() / "pre.pt")
    assert meta["variant"] == {"model": "cGNN", "train_data": "Exp", "rotate": False,
                               "aug": False, "pretrained": pre, "offsets": "none"}


# --- the validation metrics ------------------------------------------------------------------

class _Constant(nn.Module):
    """A network that answers the same normalised displacement ``v`` at every point and the
    same normalised force change ``f`` (the metrics then follow by hand)."""

    def __init__(self, v: tuple[float, float, float], f: float) -> None:
        super().__init__()
        self.v, self.f = torch.tensor(v), f

    def forward(self, points, cond, mask=None, neighbours=None):
        return self.v.expand_as(points).clone(), torch.full((len(points),), self.f)


def _tiny_states() -> StateTensors:
    """Four states of five points; point 4 is invalid in state 3; the tip presses 2 mm per
    state; the force 0, 1, 3, 4 N."""
    rng = np.random.default_rng(5)
    pts = rng.uniform(0.0, 0.1, (4, 5, 3)).astype(np.float32)
    valid = np.ones((4, 5), bool)
    valid[3, 4] = False
    pts[3, 4] = 0.0
    tip = np.array([[0.05, 0.05, -2e-3 * s] for s in range(4)], np.float32)
    return StateTensors(torch.from_numpy(pts), torch.from_numpy(valid), torch.from_numpy(tip),
                        torch.tensor([0.0, 1.0, 3.0, 4.0]), {})


def test_evaluate_pairs_is_the_hand_computed_mean_over_all_examples() -> None:
    """Every example's predicted points are its start moved by v x disp_scale (every press
    is 2 mm or more: the gate is 1), its force change f x force_scale; L_d over the points
    valid at both ends; the means are over the examples, across batches of two."""
    states = _tiny_states()
    pairs = torch.tensor([[0, 1], [0, 3], [1, 2]])
    norm = Normaliser((0.05, 0.05, 0.0), 0.03, disp_scale=0.002, force_scale=0.5, extent=0.08,
                      envelope=Envelope(2e-3, 6e-3, -6e-3, 0.0, 1.0, 4.0))
    v, f = (1.0, -0.5, 2.0), 3.0
    pts, valid = states.points.double().numpy(), states.valid.numpy()
    move = np.array(v) * 0.002
    ld, err = [], []
    for s, e in pairs.tolist():
        both = valid[s] & valid[e]
        d = np.linalg.norm(pts[s] + move - pts[e], axis=1)
        ld.append(d[both].mean())
        err.append(f * 0.5 - (float(states.force[e]) - float(states.force[s])))
    ld, err = np.array(ld), np.array(err)
    for balanced, loss in ((False, 88.0 * ld + err**2),
                           (True, ld / 0.002 + (err / 0.5) ** 2)):
        out = evaluate_pairs(_Constant(v, f), norm, states, pairs, alpha=88.0, batch=2,
                             balanced=balanced)
        assert out["val_loss"] == pytest.approx(loss.mean(), rel=1e-5)
        assert out["val_ld_mm"] == pytest.approx(ld.mean() * 1e3, rel=1e-5)
        assert out["val_force_abs_n"] == pytest.approx(np.abs(err).mean(), rel=1e-5)


def test_evaluate_pairs_puts_the_model_in_eval_mode() -> None:
    """Validation never runs a network in training mode (dropout, norms)."""
    model = _Constant((0.0, 0.0, 0.0), 0.0).train()
    norm = Normaliser((0.05, 0.05, 0.0), 0.03, 0.002, 0.5, 0.08)
    evaluate_pairs(model, norm, _tiny_states(), torch.tensor([[0, 1]]), alpha=88.0)
    assert not model.training


# --- the run's files -------------------------------------------------------------------------

def test_a_run_folder_names_best_last_and_log(tmp_path: Path) -> None:
    """A run folder's three files, and no notes before a last.pt exists."""
    files = RunFiles.in_folder(tmp_path)
    assert (files.best, files.last, files.log) == (tmp_path / "best.pt", tmp_path / "last.pt",
                                                   tmp_path / "log.csv")
    assert run_notes(files.last) == []                     # no last.pt yet: no notes


def test_a_checkpoint_holds_the_run_and_with_ema_the_stepped_weights() -> None:
    """What a checkpoint holds after an epoch: the kept (averaged) weights as "model", the
    stepped ones as "trained" only with ema, the optimizer, where the run stands, its config
    and normaliser; the run's own tensors (the writer copies what it keeps)."""
    stepped, averaged = nn.Linear(2, 1), nn.Linear(2, 1)
    norm = Normaliser((0.0, 0.0, 0.0), 0.03, 0.002, 0.5, 0.08)
    run = SimpleNamespace(kept=averaged, model=stepped, averaged=averaged, best_val=0.5,
                          best_epoch=1, optimizer=adam(stepped.parameters(), 1e-3),
                          meta={"config": {"k": 5}}, norm=norm)
    state = checkpoint_state(run, 3)
    assert (state["epoch"], state["best_epoch"], state["best_val"]) == (3, 1, 0.5)
    assert state["model"]["weight"].data_ptr() == averaged.weight.data_ptr()
    assert state["trained"]["weight"].data_ptr() == stepped.weight.data_ptr()
    assert state["config"] == {"k": 5} and state["norm"] == norm.to_dict()
    assert state["optimizer"]["param_groups"][0]["lr"] == 1e-3
    run.kept, run.averaged = stepped, None
    assert "trained" not in checkpoint_state(run, 3)


def test_the_device_is_resolved_or_refused() -> None:
    """cpu as asked, auto to CUDA only where torch has it, cuda refused without it."""
    assert resolve_device("cpu") == torch.device("cpu")
    auto = resolve_device("auto")
    assert auto.type == ("cuda" if torch.cuda.is_available() else "cpu")
    if not torch.cuda.is_available():
        with pytest.raises(BadInput, match="--device cuda: this torch has no CUDA device"):
            resolve_device("cuda")

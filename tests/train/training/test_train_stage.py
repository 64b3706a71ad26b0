"""Training and evaluation of the cGNN on a surface with a known, closed-form dent."""

from __future__ import annotations

import csv
import json
from pathlib import Path

import h5py
import numpy as np
import pytest
import torch
from click.testing import CliRunner
from helpers.cgnn_data import dent_fold, write_dent_states

from core.errors import BadInput
from core.recording import rrd_entities
from pipeline.cli import cli
from train.evaluation.metrics_table import table2
from train.evaluation.scoring import evaluate_runs
from train.model.config import CGNNConfig
from train.training.checkpoint import load_checkpoint
from train.training.train_params import TrainInputs, TrainOptions, TrainParams
from train.training.train_stage import run_train

SMALL = CGNNConfig(edge_widths=((16, 16),) * 3, disp_widths=(32,), force_widths=(16, 8, 8))


@pytest.fixture(scope="module")
def dent(tmp_path_factory) -> tuple[Path, Path]:
    return dent_fold(tmp_path_factory.mktemp("dent"))


def _train(dent, out: Path, **kw) -> Path:
    opts = TrainOptions(**{"epochs": 2, "batch": 8, "lr": 3e-3, **kw})
    return run_train(TrainInputs(*dent), out, TrainParams(opts, SMALL, "cpu")).best


def _weights(path: Path) -> dict[str, torch.Tensor]:
    return load_checkpoint(path)["model"]


def test_training_learns_the_dent(dent, tmp_path) -> None:
    _train(dent, tmp_path / "run", epochs=12)
    with open(tmp_path / "run" / "log.csv") as f:
        rows = list(csv.DictReader(f))
    assert len(rows) == 12
    first, last = float(rows[0]["val_loss"]), min(float(r["val_loss"]) for r in rows)
    assert last < 0.5 * first
    assert (tmp_path / "run" / "best.pt").is_file() and (tmp_path / "run" / "last.pt").is_file()


def test_a_resumed_run_equals_an_uninterrupted_one(dent, tmp_path) -> None:
    _train(dent, tmp_path / "whole", epochs=3)
    _train(dent, tmp_path / "killed", epochs=1)         # stopped after its first epoch
    _train(dent, tmp_path / "killed", epochs=3)         # run again: resumes at epoch 2
    a, b = _weights(tmp_path / "whole" / "last.pt"), _weights(tmp_path / "killed" / "last.pt")
    for k in a:
        torch.testing.assert_close(a[k], b[k], atol=1e-6, rtol=1e-5)
    assert load_checkpoint(tmp_path / "killed" / "last.pt")["epoch"] == 2


def test_a_run_killed_between_writes_resumes_from_the_last(dent, tmp_path, monkeypatch) -> None:
    """Files written after epoch 0 alone, the run killed in epoch 2 with epoch 1's row and
    state still waiting: they are lost, and the run started again trains epochs 1 and 2 to
    the uninterrupted run's weights, its log one row per epoch."""
    from train.training import loop
    from train.training.run_files import RunWriter

    _train(dent, tmp_path / "whole", epochs=3)
    monkeypatch.setattr(loop, "RunWriter", lambda files, save: RunWriter(files, save, 0))
    _train(dent, tmp_path / "killed", epochs=1)
    epoch = loop.train_epoch

    def killed_in_epoch_2(run, net, opts, e, ctx, first):
        if e == 2:
            raise KeyboardInterrupt
        return epoch(run, net, opts, e, ctx, first)

    monkeypatch.setattr(loop, "RunWriter", lambda files, save: RunWriter(files, save, 1e9))
    monkeypatch.setattr(loop, "train_epoch", killed_in_epoch_2)
    with pytest.raises(KeyboardInterrupt):
        _train(dent, tmp_path / "killed", epochs=3)
    assert load_checkpoint(tmp_path / "killed" / "last.pt")["epoch"] == 0
    monkeypatch.undo()
    _train(dent, tmp_path / "killed", epochs=3)
    a, b = _weights(tmp_path / "whole" / "last.pt"), _weights(tmp_path / "killed" / "last.pt")
    for k in a:
        torch.testing.assert_close(a[k], b[k], atol=1e-6, rtol=1e-5)
    with open(tmp_path / "killed" / "log.csv") as f:
        assert [int(r["epoch"]) for r in csv.DictReader(f)] == [0, 1, 2]


def _as_before_head_offsets(path: Path) -> None:
    """Rewrite a checkpoint as one saved before the network had head offsets: its config
    (and its meta's) with ``tip_offsets`` alone, as then."""
    state = torch.load(path, weights_only=True)
    for config in (state["config"], state["meta"]["config"]):
        config.pop("offsets", None)               # (the two may be one dict)
        config.pop("offset_width", None)
        config["tip_offsets"] = False
    torch.save(state, path)


def test_a_checkpoint_from_before_head_offsets_resumes_and_fine_tunes(dent, tmp_path) -> None:
    """A checkpoint of an older form is read in today's (:mod:`train.training.migrate`): an
    old last.pt resumes, an old best.pt starts transfer learning (the same network), instead
    of being refused."""
    _train(dent, tmp_path / "old", epochs=1)
    for name in ("best.pt", "last.pt"):
        _as_before_head_offsets(tmp_path / "old" / name)
    _train(dent, tmp_path / "old", epochs=2)                  # resumes at epoch 2
    assert load_checkpoint(tmp_path / "old" / "last.pt")["epoch"] == 1
    _as_before_head_offsets(tmp_path / "old" / "best.pt")
    data, splits = dent
    run_train(TrainInputs(data, splits, tmp_path / "old" / "best.pt"), tmp_path / "tl",
              TrainParams(TrainOptions(epochs=1, batch=8), SMALL, "cpu"))
    assert (tmp_path / "tl" / "best.pt").is_file()


def test_same_seed_same_weights_other_seed_other_weights(dent, tmp_path) -> None:
    a = _weights(_train(dent, tmp_path / "a", epochs=1, seed=3))
    b = _weights(_train(dent, tmp_path / "b", epochs=1, seed=3))
    c = _weights(_train(dent, tmp_path / "c", epochs=1, seed=4))
    assert all(torch.equal(a[k], b[k]) for k in a)
    assert not all(torch.equal(a[k], c[k]) for k in a)


def test_a_run_with_other_options_is_not_resumed(dent, tmp_path) -> None:
    _train(dent, tmp_path / "run", epochs=1)
    with pytest.raises(BadInput, match="other data, fold, options"):
        _train(dent, tmp_path / "run", epochs=2, lr=1e-2)


def test_a_manifest_of_other_data_is_refused(dent, tmp_path) -> None:
    data, splits = dent
    other = tmp_path / "other.h5"
    write_dent_states(other, seed=5)
    with pytest.raises(BadInput, match="sha256"):
        run_train(TrainInputs(other, splits), tmp_path / "run",
                  TrainParams(TrainOptions(epochs=1), SMALL, "cpu"))


def test_a_diverging_loss_names_epoch_and_batch(dent, tmp_path) -> None:
    """The largest step size the options take (1) diverges on the dent data at once."""
    with pytest.raises(BadInput, match=r"diverged at epoch 0, batch \d+"):
        _train(dent, tmp_path / "run", epochs=1, lr=TrainOptions.BOUNDS["lr"].max)


def test_aug_trains_on_a_fraction_of_the_points(dent, tmp_path) -> None:
    _train(dent, tmp_path / "aug", epochs=2, point_fraction=0.2)
    assert load_checkpoint(tmp_path / "aug" / "best.pt")["meta"]["options"]["point_fraction"] \
        == 0.2


def test_eval_of_a_do_nothing_model_measures_the_true_displacement(dent, tmp_path) -> None:
    """With the heads' last layers zeroed the model predicts no motion and no force change:
    its L_d is then each example's true mean displacement, computed here from the file."""
    data, splits = dent
    best = _train(dent, tmp_path / "run", epochs=1)
    state = load_checkpoint(best)
    for key in list(state["model"]):
        if key.startswith(("disp_head.2.", "force_head.6.")):
            state["model"][key].zero_()
    torch.save(state, best)
    result = evaluate_runs([tmp_path / "run"]).to_json()     # as metrics.json keeps it
    doc = json.loads(splits.read_text())
    with h5py.File(data) as f:
        pts, force = f["states/points"][()], f["states/force"][()]
        expect = {}
        for name in ("single", "multi"):
            ids = doc["folds"][0]["test"][name]
            s, e = f[f"{name}/start"][()][ids], f[f"{name}/end"][()][ids]
            dist = np.linalg.norm(pts[e] - pts[s], axis=-1)
            expect[name] = (dist.mean(1), dist.max(1), force[e] - force[s])
    m = result["runs"][0]["metrics"]
    for name, (ld, ld_max, df) in expect.items():
        assert m[name]["ld_mean_mm"] == pytest.approx(ld.mean() * 1e3, rel=1e-4)
        assert m[name]["ld_max_mm"] == pytest.approx(ld_max.mean() * 1e3, rel=1e-4)
        assert m[name]["force_mse_n2"] == pytest.approx(np.mean(df**2), rel=1e-4)
        assert m[name]["force_abs_n"] == pytest.approx(np.mean(np.abs(df)), rel=1e-4)
    assert result["overall"][0]["label"] == "cGNN/Exp"


def test_train_and_eval_commands_write_runs_tables_and_recordings(dent, tmp_path) -> None:
    data, splits = dent
    run = tmp_path / "run"
    res = CliRunner().invoke(cli, ["-q", "train", "--data", str(data), "--splits", str(splits),
                                   "--out", str(run), "--epochs", "1", "--batch", "8"])
    assert res.exit_code == 0, res.output
    assert {"/loss/train", "/loss/val", "/val/ld_mm"} <= set(rrd_entities(run / "train.rrd"))
    out = tmp_path / "metrics.json"
    res = CliRunner().invoke(cli, ["-q", "eval", str(run), "--out", str(out)])
    assert res.exit_code == 0, res.output
    assert "| cGNN/Exp | Exp |" in out.with_suffix(".md").read_text()
    ents = set(rrd_entities(out.with_suffix(".rrd")))
    assert {"/surface/true", "/surface/predicted", "/force/true", "/force/predicted",
            "/table"} <= ents


def test_train_bad_input_is_one_line_and_exit_2(dent, tmp_path) -> None:
    data, splits = dent
    bad = tmp_path / "bad.json"
    bad.write_text("[1, 2")
    res = CliRunner().invoke(cli, ["-q", "train", "--data", str(data), "--splits", str(bad),
                                   "--out", str(tmp_path / "run")])
    assert res.exit_code == 2 and "bad.json" in res.output and "Traceback" not in res.output
    assert not (tmp_path / "run").exists()
    res = CliRunner().invoke(cli, ["-q", "train", "--data", str(data), "--splits", str(splits),
                                   "--fold", "7", "--out", str(tmp_path / "run")])
    assert res.exit_code == 2 and "--fold 7" in res.output


def test_scarcity_retrains_on_nested_subsets_with_and_without_transfer(dent, tmp_path) -> None:
    data, splits = dent
    pre = tmp_path / "pre"
    _train(dent, pre, epochs=1)
    run = tmp_path / "tl"
    run_train(TrainInputs(data, splits, pre / "best.pt"), run,
              TrainParams(TrainOptions(epochs=1, batch=8), SMALL, "cpu"))
    out = tmp_path / "metrics.json"
    res = CliRunner().invoke(cli, ["-q", "eval", str(run), "--out", str(out), "--scarcity",
                                   "--no-rrd"])
    assert res.exit_code == 0, res.output
    rows = json.loads(out.read_text())["scarcity"]
    n_train = len(json.loads(splits.read_text())["folds"][0]["train"]["groups"])
    assert sorted({r["groups"] for r in rows}) == list(range(1, n_train + 1))
    assert {r["predictor"] for r in rows} == {"TL", "no TL", "nothing moves", "nearest press",
                                             "force, linear"} and len(rows) == 5 * n_train
    for r in rows:          # a model's intervals, calibrated on the fold's validation presses
        model = r["predictor"] in ("TL", "no TL")
        assert ("points_90" in r) == model and ("force_90" in r) == model
        if model:
            assert 0 <= r["points_90"] <= 1 and 0 <= r["force_90"] <= 1
        banded = model and r["groups"] == 1          # the fewest presses: judged by chance's range
        assert (r.get("points_90_low") is not None) == banded
    header = out.with_suffix(".scarcity.csv").read_text().splitlines()[0]
    assert header.endswith("points_90,force_90,points_90_low,points_90_high,force_90_low,"
                           "force_90_high")
    assert out.with_suffix(".scarcity.png").stat().st_size > 0


def test_a_run_records_its_variant_and_a_fine_tuned_one_its_pre_training(dent, tmp_path
                                                                         ) -> None:
    """The variant is structured fields in the checkpoint, kept when the pre-training run is
    gone; the label is built from them, never parsed."""
    data, splits = dent
    pre = tmp_path / "pre"
    _train(dent, pre, epochs=1, point_fraction=0.5)
    run = tmp_path / "tl"
    run_train(TrainInputs(data, splits, pre / "best.pt"), run,
              TrainParams(TrainOptions(epochs=1, batch=8, rotate=True), SMALL, "cpu"))
    (pre / "best.pt").rename(tmp_path / "moved.pt")
    variant = load_checkpoint(run / "best.pt")["meta"]["variant"]
    assert variant == {"model": "cGNN", "train_data": "Exp", "rotate": True, "aug": False,
                       "pretrained": {"model": "cGNN", "train_data": "Exp", "rotate": False,
                                      "aug": True, "pretrained": None, "offsets": "none"},
                       "offsets": "none"}
    result = evaluate_runs([run]).to_json()
    assert result["runs"][0]["variant"] == variant
    assert result["overall"][0]["label"] == "cGNN/aug Exp (TL)"


def test_fine_tuned_runs_that_differ_only_in_rotation_are_not_pooled(dent, tmp_path) -> None:
    """Their Table 2 label is the same (a fine-tuned run's names its pre-training only), but
    they are two variants: evaluation groups by every field, and the table tells them apart."""
    data, splits = dent
    pre = tmp_path / "pre"
    _train(dent, pre, epochs=1)
    runs = []
    for rotate in (False, True):
        runs.append(tmp_path / f"tl_rot{rotate}")
        run_train(TrainInputs(data, splits, pre / "best.pt"), runs[-1],
                  TrainParams(TrainOptions(epochs=1, batch=8, rotate=rotate), SMALL, "cpu"))
    scores = evaluate_runs(runs)
    result = scores.to_json()
    assert [r["label"] for r in result["overall"]] == ["cGNN/Exp (TL)"] * 2
    assert [r["variant"]["rotate"] for r in result["overall"]] == [False, True]
    assert [r["folds"] for r in result["overall"]] == [1, 1]
    for row, run in zip(result["overall"], result["runs"], strict=True):
        assert row["metrics"]["all"]["ld_mean_mm"] == run["metrics"]["all"]["ld_mean_mm"]
    table = table2(scores)
    assert "| cGNN/Exp from cGNN/Exp | Exp |" in table
    assert "| cGNN/rot Exp from cGNN/Exp | Exp |" in table


def test_balanced_loss_puts_each_term_in_its_scale() -> None:
    from train.data import Batch
    from train.model.normalise import Normaliser
    from train.model.si_units import BatchPrediction, loss_sum
    from train.training.loop import learning_rate

    pts = torch.zeros(1, 2, 3)
    b = Batch(pts, pts + torch.tensor([0.0, 0.0, 0.002]), torch.ones(1, 2, dtype=torch.bool),
              torch.zeros(1, 6), torch.tensor([1.0]))
    p = BatchPrediction(pts, torch.tensor([4.0]))                      # 2 mm and 3 N off
    norm = Normaliser((0.0, 0.0, 0.0), 0.05, disp_scale=0.001, force_scale=2.0, extent=0.1)
    assert float(loss_sum(p, b, 88.0)) == pytest.approx(88 * 0.002 + 9.0)
    assert float(loss_sum(p, b, 88.0, norm)) == pytest.approx(2.0 + 2.25)
    cosine = TrainOptions(epochs=11, lr=1e-3, schedule="cosine")
    assert learning_rate(cosine, 0) == pytest.approx(1e-3)
    assert learning_rate(cosine, 10) == pytest.approx(1e-5)
    assert learning_rate(cosine, 5) == pytest.approx(1e-3 * (0.01 + 0.99 / 2))
    assert learning_rate(TrainOptions(epochs=11, lr=1e-3), 7) == 1e-3


def test_patience_stops_early_and_a_resumed_run_stops_alike(dent, tmp_path) -> None:
    """A validation loss that cannot improve (lr ~ 0) stops the run after `patience` epochs;
    started again with more epochs, it does not train on."""
    opts = {"epochs": 12, "lr": 1e-12, "patience": 2}
    _train(dent, tmp_path / "run", **opts)
    with open(tmp_path / "run" / "log.csv") as f:
        epochs = [int(r["epoch"]) for r in csv.DictReader(f)]
    assert epochs == [0, 1, 2]
    assert load_checkpoint(tmp_path / "run" / "last.pt")["best_epoch"] == 0
    assert load_checkpoint(tmp_path / "run" / "best.pt")["epoch"] == 0   # kept, not the last
    _train(dent, tmp_path / "run", **{**opts, "epochs": 20})
    assert load_checkpoint(tmp_path / "run" / "last.pt")["epoch"] == 2


def test_ema_keeps_the_average_of_the_steps_and_resumes_alike(dent, tmp_path) -> None:
    """With one step per epoch, the kept model is the average a_t = d a_(t-1) + (1 - d) w_t
    of the stepped weights w_t (w_0: the seeded start), computed here from each epoch's
    checkpoint; a run resumed epoch by epoch equals an uninterrupted one."""
    from train.model.cgnn import CGNN

    opts = {"batch": 10_000, "ema": 0.75, "seed": 3}
    torch.manual_seed(3)
    avg = {k: v.clone() for k, v in CGNN(SMALL).state_dict().items()}       # w_0
    for epochs in (1, 2, 3):
        _train(dent, tmp_path / "steps", epochs=epochs, **opts)
        state = load_checkpoint(tmp_path / "steps" / "last.pt")
        avg = {k: 0.75 * v + 0.25 * state["trained"][k] for k, v in avg.items()}
    for name, value in state["model"].items():
        torch.testing.assert_close(value, avg[name], rtol=1e-5, atol=1e-7)
    _train(dent, tmp_path / "whole", epochs=3, **opts)
    whole = load_checkpoint(tmp_path / "whole" / "last.pt")
    for key in ("model", "trained"):
        for name, value in whole[key].items():
            assert torch.equal(value, state[key][name]), (key, name)
    assert "trained" not in load_checkpoint(_train(dent, tmp_path / "plain", epochs=1))


def test_tip_offsets_feed_the_first_layer_and_need_the_condition(dent, tmp_path) -> None:
    from train.model.cgnn import CGNN

    config = CGNNConfig(offsets="graph")
    assert CGNNConfig.from_dict(config.to_dict()) == config
    assert CGNN(config).convs[0].mlp[0].in_features == 2 * 9
    with pytest.raises(BadInput, match="noCond"):
        CGNNConfig(offsets="graph", use_condition=False)
    res = CliRunner().invoke(cli, ["train", "--data", str(dent[0]), "--splits", str(dent[1]),
                                   "--out", str(tmp_path / "r"), "--offsets", "graph",
                                   "--no-cond"])
    assert res.exit_code == 2 and "which noCond removes" in res.output

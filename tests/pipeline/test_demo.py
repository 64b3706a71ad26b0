"""`pipeline demo` runs every stage end to end, leaves each output and recording readable, and
skips what did not change."""

from __future__ import annotations

import json
from pathlib import Path

import h5py
import pytest
import torch
from click.testing import CliRunner

from core.recording import rrd_entities
from data_schema import validate_h5
from data_schema.json_docs import validate_folds
from data_schema.states import validate_states
from data_schema.synced import SYNCED
from ingest.mcap_io import read_raw_mcap
from pipeline.cli import cli
from pipeline.demo_plan import NETWORKS, QUICK, RECIPE, SMOKE, Lab, Pretraining, demo_steps
from train.generic_model import SHIPPED, SHIPPED_CURVED


def test_demo_runs_every_stage_and_skips_unchanged_ones(tmp_path):
    """The generic pre-training made here: one model, pre-trained once on the prior's MSM
    data, is where every fold's TL run starts."""
    out = tmp_path / "demo"
    generic = ["-q", "demo", "--smoke", "--pretraining", Pretraining.GENERIC, "--out",
               str(out)]
    res = CliRunner().invoke(cli, generic)
    assert res.exit_code == 0, res.output
    assert (out / "session" / "truth.h5").is_file()
    raw = read_raw_mcap(out / "session.mcap")
    assert len(raw.phantom_markers) == 25 and len(raw.indenter_markers) == 4
    validate_h5(out / "session_synced.h5", SYNCED)
    validate_states(out / "session_states.h5")
    assert len(validate_folds(out / "splits.json")["folds"]) == 2
    validate_states(out / "msm" / "prior.h5")
    with h5py.File(out / "msm" / "prior.h5") as f:          # phantoms drawn from the prior
        assert "phantoms/k_between" in f and f["states/points"].shape[1] == 65
    assert not (out / "msm" / "fold0").exists()              # no fit, no MSM per fold
    metrics = json.loads((out / "metrics.json").read_text())
    assert {Path(r["run"]).name for r in metrics["runs"]} == {
        "generic", "exp_tl_fold0", "exp_tl_fold1", "exp_notl_fold0", "exp_notl_fold1"}
    for k in range(2):                                    # TL starts from the one generic model
        meta = torch.load(out / "runs" / f"exp_tl_fold{k}" / "best.pt", weights_only=False)
        assert Path(meta["meta"]["init"]).parent.name == "generic"
    assert all(set(r["references"]) == {"nothing moves", "nearest press", "force, linear"}
               for r in metrics["runs"])
    md = (out / "metrics.md").read_text()
    assert "*reference: nearest press*" in md
    scarcity = json.loads((out / "scarcity" / "fold0.json").read_text())["scarcity"]
    assert {r["predictor"] for r in scarcity} >= {"TL", "no TL", "nearest press"}
    for rrd in ("session/recording.rrd", "session.rrd", "session_synced.rrd",
                "session_states.rrd", "splits.rrd", "msm/prior.rrd", "runs/generic/train.rrd",
                "metrics.rrd"):
        assert rrd_entities(out / rrd), rrd
    for line in res.output.splitlines():                  # sync met its targets
        if line.strip().startswith("MISSED"):
            assert "sync" not in line, line
    assert "transfer learning, pooled over folds" in res.output
    steps = demo_steps(out, 0, SMOKE, pretraining=Pretraining.GENERIC)
    times = json.loads((out / "demo_times.json").read_text())     # every step timed, once
    assert sorted(tuple(s["args"]) for s in times["steps"]) == sorted(s.args for s in steps)
    assert not any(s["skipped"] for s in times["steps"])
    assert times["stages"]["train (pre-training)"]["ran"] == 1
    assert times["stages"]["simulate --prior"]["ran"] == 1
    tunes = [s for s in times["steps"] if s["stage"] == "train (fine-tuning)"]
    assert len(tunes) == 2 * SMOKE.folds and all(s["seconds"] > 0 for s in tunes)
    assert times["host_speed_s"] is None and times["host_speed"].startswith("absent")
    again = CliRunner().invoke(cli, generic)
    assert again.exit_code == 0, again.output
    assert again.output.count("(unchanged since its last run: skipped)") == len(steps)
    times = json.loads((out / "demo_times.json").read_text())
    assert all(s["skipped"] and s["seconds"] == 0 for s in times["steps"])
    (out / "msm" / "prior_splits.json").unlink()   # the prior's split gone: what reads it, and
    third = CliRunner().invoke(cli, generic)   # on
    assert third.exit_code == 0, third.output
    lines = third.output.splitlines()
    rerun = [line for line, after in zip(lines, lines[1:] + [""], strict=True)
             if "$ pipeline" in line and "skipped" not in after]
    for name in ("prior_splits.json", "runs/generic ", "exp_tl_fold0 ", "exp_tl_fold1 ",
                 "metrics.json"):
        assert any(name in line for line in rerun), name
    assert not any("exp_notl" in line or "synth" in line for line in rerun
                   if "pipeline eval" not in line), rerun


def test_the_per_fold_pretraining_fits_each_fold_on_another_labs_phantom(tmp_path):
    """A 120 x 80 mm block with 12 scattered markers at 250 Hz: every stage takes its points,
    footprint and rate, from synth to eval, and each fold's MSM is fitted on that fold's
    training presses only and sampled at the lab's markers (the wiring; --smoke learns
    nothing)."""
    out = tmp_path / "demo"
    res = CliRunner().invoke(cli, ["-q", "demo", "--smoke", "--pretraining", "per-fold",
                                   "--out", str(out), "--markers", "scattered:12", "--size",
                                   "120x80", "--mocap-rate", "250"])
    assert res.exit_code == 0, res.output
    raw = read_raw_mcap(out / "session.mcap")
    assert len(raw.phantom_markers) == 12 and raw.markers.rate_hz == 250
    with h5py.File(out / "session_states.h5") as f:
        assert f["states/points"].shape[1] == 13
        assert json.loads(f.attrs["point_names"]) == [*raw.phantom_markers, "tip"]
        assert tuple(f.attrs["footprint_m"]) == pytest.approx((0.12, 0.08))
    for k, fold in enumerate(validate_folds(out / "splits.json")["folds"]):
        d = out / "msm" / f"fold{k}"                      # the MSM fitted per fold ...
        fit = json.loads((d / "params.json").read_text())
        assert fit["mean_distance_m"] < fit["still_distance_m"]
        fitted = {s["sequence"] for s in fit["per_sequence"]}   # ... on its training presses
        assert fitted and fitted <= set(fold["train"]["groups"])
        assert not fitted & set(fold["test"]["groups"])
        validate_states(d / "msm.h5")
        with h5py.File(d / "msm.h5") as f:                 # the lab's 12 markers + the tip
            assert f["states/points"].shape[1] == 13 and "layout" in f.attrs
            assert tuple(f.attrs["footprint_m"]) == pytest.approx((0.12, 0.08))
        meta = torch.load(out / "runs" / f"exp_tl_fold{k}" / "best.pt", weights_only=False)
        assert Path(meta["meta"]["init"]).parent.name == f"msm_fold{k}"   # its own MSM's
    metrics = json.loads((out / "metrics.json").read_text())
    assert {Path(r["run"]).name for r in metrics["runs"]} == {
        "msm_fold0", "msm_fold1", "exp_tl_fold0", "exp_tl_fold1", "exp_notl_fold0",
        "exp_notl_fold1"}
    md = (out / "metrics.md").read_text()
    per_fold = md[md.index("Mean L_d per fold on Exp"):].splitlines()   # the lab's folds ...
    assert "cGNN/rot MSM" not in per_fold[2] and "cGNN/MSM (TL)" in per_fold[2]   # ... only
    assert "MSM fitted per fold on its training presses" in res.output
    times = json.loads((out / "demo_times.json").read_text())
    assert times["stages"]["train (pre-training)"]["ran"] == SMOKE.folds


def test_a_pretraining_the_plan_does_not_know_is_refused_not_run_as_another(tmp_path):
    """The plan knows its pre-trainings as an enum; the command line refuses any other word
    in one line naming the option and the words it takes, before any step."""
    out = tmp_path / "demo"
    res = CliRunner().invoke(cli, ["demo", "--smoke", "--pretraining", "per_fold", "--out",
                                   str(out)])
    assert res.exit_code == 2 and not out.exists()
    assert res.output.strip() == ("error: --pretraining 'per_fold': must be one of shipped, "
                                  "generic, per-fold, solid")
    assert [p.value for p in Pretraining] == ["shipped", "generic", "per-fold", "solid"]


@pytest.mark.parametrize("pretraining", list(Pretraining))
def test_every_pretraining_has_a_plan_by_its_member_or_its_word(tmp_path, pretraining):
    """Each pre-training plans steps, the same by its word alone ("per-fold", a plain str) as
    by its member; the shipped model's and the solid's fine-tune the shipped file."""
    steps = demo_steps(tmp_path, 0, SMOKE, pretraining=pretraining)
    word = str(pretraining.value)
    assert type(word) is str and [s.args for s in steps] == \
        [s.args for s in demo_steps(tmp_path, 0, SMOKE, pretraining=word)]
    inits = {s.args[s.args.index("--init") + 1] for s in steps if "--init" in s.args}
    assert (str(SHIPPED) in inits) == pretraining.from_shipped


@pytest.mark.parametrize("network", list(NETWORKS))
def test_network_changes_every_training_runs_network_and_nothing_else(tmp_path, network):
    """``--network`` adds its flags after the recipe's to every training run (pre-training
    and both fine-tunings); every other step is the same."""
    ours = demo_steps(tmp_path, 0, SMOKE, pretraining=Pretraining.GENERIC)
    other = demo_steps(tmp_path, 0, SMOKE, recipe=NETWORKS[network],
                       pretraining=Pretraining.GENERIC)
    trains = [(a.args, b.args) for a, b in zip(ours, other, strict=True) if a.args[0] == "train"]
    assert len(trains) == 1 + 2 * SMOKE.folds              # pre-training and two fine-tunings
    extra = NETWORKS[network][len(RECIPE):]
    for plain, changed in trains:
        at = plain.index(RECIPE[-1]) + 1
        assert changed == (*plain[:at], *extra, *plain[at:])
    assert [a.args for a in ours if a.args[0] != "train"] == \
        [b.args for b in other if b.args[0] != "train"]


def test_every_lab_and_seed_fine_tunes_from_the_same_generic_model(tmp_path):
    """The generic model's steps (the prior's data, its split, the pre-training) are the same
    commands whatever the lab's markers, footprint or rate and the demo's seed; a fine-tuning
    starts from it."""
    def generic(seed: int, lab: Lab) -> list[tuple[str, ...]]:
        return [s.args for s in demo_steps(tmp_path, seed, QUICK, lab=lab,
                                           pretraining=Pretraining.GENERIC)
                if s.stage in ("simulate --prior", "train (pre-training)")
                or s.args[:2] == ("split", str(tmp_path / "msm" / "prior.h5"))]

    mine = generic(0, Lab())
    assert len(mine) == 3
    assert generic(2, Lab(markers="6x6", marker_pitch_mm=12, mocap_rate_hz=300)) == mine
    assert generic(1, Lab(markers="scattered:20", size_mm="150x80")) == mine
    tl = [s for s in demo_steps(tmp_path, 1, QUICK, pretraining=Pretraining.GENERIC)
          if "exp_tl_fold3" in str(s.outputs[0])]
    assert tl[0].inputs[-1] == tmp_path / "runs" / "generic" / "best.pt"


def test_by_default_every_fold_fine_tunes_from_the_shipped_model(tmp_path):
    """The default pre-training is none: no prior's data, no pre-training step; every TL
    run starts from the package's generic model, and eval scores the fine-tuned runs only
    (the shipped model's own test set is the prior's, not here)."""
    steps = demo_steps(tmp_path, 0, QUICK)
    assert not any(s.stage in ("simulate --prior", "train (pre-training)") for s in steps)
    tl = [s for s in steps if s.args[0] == "train" and "--init" in s.args]
    assert len(tl) == QUICK.folds
    assert all(s.args[s.args.index("--init") + 1] == str(SHIPPED) for s in tl)
    ev = [s for s in steps if s.args[0] == "eval" and "--scarcity" not in s.args][0]
    assert not any(str(SHIPPED.parent) == a for a in ev.args)
    assert {Path(a).name for a in ev.args[1:-2]} == {
        f"exp_{v}_fold{k}" for v in ("tl", "notl") for k in range(QUICK.folds)}


def test_a_lab_with_a_lump_and_a_layer_is_evaluated_over_the_lump(tmp_path):
    """``--inclusion`` and ``--layer`` make the twin's phantom not uniform (synth's options,
    tests/sim/twin); eval then splits the test presses over the lump and away from it, from
    its truth (tests/train/evaluation/test_lump.py)."""
    steps = demo_steps(tmp_path, 0, SMOKE, lab=Lab(inclusions=("72,23,10,12,3",),
                                                   layer="3,4"))
    synth = steps[[s.args[0] for s in steps].index("synth")].args
    assert synth[synth.index("--inclusion") + 1] == "72,23,10,12,3"
    assert synth[synth.index("--layer") + 1] == "3,4"
    ev = [s for s in steps if s.args[0] == "eval" and "--scarcity" not in s.args][0].args
    assert ev[ev.index("--truth") + 1] == str(tmp_path / "session" / "truth.h5")
    uniform = demo_steps(tmp_path, 0, SMOKE)
    assert not any("--truth" in s.args or "--inclusion" in s.args for s in uniform)


def test_a_lab_with_a_lump_learns_the_force_from_unturned_presses_only(tmp_path):
    """An inclusion makes the force depend on where the phantom is pressed: every run trained
    on the lab or its solid keeps --rotate (the recipe's) and adds --no-rotate-force; a
    uniform lab or one with a top layer (the same across the footprint) does not, nor does
    the pre-training on a fitted MSM (uniform)."""
    lump = demo_steps(tmp_path, 0, QUICK, lab=Lab(inclusions=("72,23,10,12,3",)),
                      pretraining=Pretraining.SOLID)
    trains = [s.args for s in lump if s.args[0] == "train"]
    assert len(trains) == 4 * QUICK.folds          # TL, scratch, the solid's and its TL
    assert all("--no-rotate-force" in a for a in trains)
    for lab in (Lab(), Lab(layer="3,4")):
        steps = demo_steps(tmp_path, 0, QUICK, lab=lab, pretraining=Pretraining.SOLID)
        assert not any("--no-rotate-force" in s.args for s in steps)
    per_fold = demo_steps(tmp_path, 0, QUICK, lab=Lab(inclusions=("72,23,10,12,3",)),
                          pretraining=Pretraining.PER_FOLD)      # the fitted MSM is uniform
    on_msm = [s.args for s in per_fold if s.stage == "train (pre-training)"]
    assert on_msm and not any("--no-rotate-force" in a for a in on_msm)
    assert all("--no-rotate-force" in s.args for s in per_fold
               if s.stage == "train (fine-tuning)")


@pytest.mark.parametrize("args, words", [
    (["--inclusion", "150,50,10,12,3"], "outside"), (["--layer", "40,3"], "thinner")])
def test_a_lump_or_layer_synth_would_refuse_stops_the_demo_before_it_starts(tmp_path, args,
                                                                             words):
    out = tmp_path / "demo"
    res = CliRunner().invoke(cli, ["demo", "--smoke", "--out", str(out), *args])
    assert res.exit_code == 2 and words in res.output
    assert len(res.output.strip().splitlines()) == 1 and not out.exists()


@pytest.mark.parametrize("network", ["tip-offsets", "paper"])
def test_another_network_than_the_shipped_models_is_refused_before_any_step(tmp_path,
                                                                            network):
    """The shipped generic model is the recipe's network: fine-tuning another from it would
    fail in every fold, so the demo says so in one line and writes nothing."""
    out = tmp_path / "demo"
    res = CliRunner().invoke(cli, ["-q", "demo", "--smoke", "--network", network, "--out",
                                   str(out)])
    assert res.exit_code == 2 and not out.exists()
    assert "--pretraining generic" in res.output + res.stderr


def test_the_quick_demo_fine_tunes_longer_than_its_scarcity_study_retrains(tmp_path):
    """Every fold's TL and scratch run trains QUICK.finetune_epochs; the scarcity study's
    runs are retrained for QUICK.scarcity_epochs (fewer: 16 runs a demo)."""
    steps = demo_steps(tmp_path, 0, QUICK, pretraining=Pretraining.GENERIC)
    tunes = [s.args for s in steps if s.stage == "train (fine-tuning)"]
    assert len(tunes) == 2 * QUICK.folds
    assert all(a[a.index("--epochs") + 1] == str(QUICK.finetune_epochs) for a in tunes)
    studies = [s.args for s in steps if "--scarcity" in s.args]
    assert len(studies) == QUICK.scarcity_folds
    assert all(a[a.index("--scarcity-epochs") + 1] == str(QUICK.scarcity_epochs)
               for a in studies)
    assert QUICK.scarcity_epochs < QUICK.finetune_epochs


def test_the_solid_pretraining_runs_beside_the_shipped_models(tmp_path):
    """``--pretraining solid``: the shipped model's TL and scratch runs as by default, and per
    fold the solid fitted on that fold's training presses with the session's interior,
    pressed at the lab's markers, the shipped model pre-trained on it, and a third run per
    fold fine-tuned from there; eval scores the three, over the lump too."""
    lab = Lab(inclusions=("72,23,10,12,3",))
    steps = demo_steps(tmp_path, 0, QUICK, lab=lab, pretraining=Pretraining.SOLID)
    fits = [s.args for s in steps if s.args[0] == "fit-solid"]
    assert len(fits) == QUICK.folds
    for k, args in enumerate(fits):
        assert args[args.index("--fold") + 1] == str(k)
        assert args[args.index("--session") + 1] == str(tmp_path / "session")
    sims = [s.args for s in steps if s.args[:2] == ("simulate", "--solid")]
    assert [a[a.index("--locations") + 1] for a in sims] == [str(QUICK.solid_locations)] * 5
    pre = {s.outputs[0].parent.name: s for s in steps if s.stage == "train (pre-training)"}
    assert sorted(pre) == [f"solid_fold{k}" for k in range(QUICK.folds)]
    assert all(s.args[s.args.index("--init") + 1] == str(SHIPPED) for s in pre.values())
    solid_tl = {s.outputs[0].parent.name: s.args for s in steps
                if s.outputs and s.outputs[0].parent.name.startswith("exp_solid_")}
    assert sorted(solid_tl) == [f"exp_solid_fold{k}" for k in range(QUICK.folds)]
    args = solid_tl["exp_solid_fold3"]
    assert args[args.index("--init") + 1] == str(tmp_path / "runs" / "solid_fold3" / "best.pt")
    ev = [s for s in steps if s.args[0] == "eval" and "--scarcity" not in s.args][0].args
    assert {Path(a).name for a in ev if "exp_" in a} == {
        f"exp_{v}_fold{k}" for v in ("tl", "notl", "solid") for k in range(QUICK.folds)}
    assert "--truth" in ev


def test_a_curved_lab_is_not_given_a_flat_simulator(tmp_path) -> None:
    """--shape with a pre-training that fits the flat MSM to the lab is refused before any
    step runs; the shipped model's plan synthesises the curved lab, and its TL runs and its
    solid's pre-training start from the generic model for curved labs."""
    from core.errors import BadInput

    lab = Lab(shape="dome:30")
    with pytest.raises(BadInput, match="flat"):
        demo_steps(tmp_path, 0, SMOKE, lab=lab, pretraining=Pretraining.PER_FOLD)
    synth = demo_steps(tmp_path, 0, SMOKE, lab=lab)[0].args
    at = synth.index("--shape")
    assert synth[0] == "synth" and synth[at + 1] == "dome:30"
    steps = demo_steps(tmp_path, 0, SMOKE, lab=lab, pretraining=Pretraining.SOLID)
    starts = {s.outputs[0].parent.name: s.args[s.args.index("--init") + 1] for s in steps
              if s.args[0] == "train" and "--init" in s.args}
    assert {starts[f"exp_tl_fold{k}"] for k in range(SMOKE.folds)} == {str(SHIPPED_CURVED)}
    assert {starts[f"solid_fold{k}"] for k in range(SMOKE.folds)} == {str(SHIPPED_CURVED)}

"""The cGNN at the extremes: the order of the points (ties on a regular grid), no press, and
inputs beyond the training envelope. Known truth: a permutation of the points permutes the
answer and changes nothing else; a tip that does not move moves nothing and changes no force;
a brute-force kNN where there are no ties."""

from __future__ import annotations

import io
import json
import warnings
from dataclasses import replace
from pathlib import Path

import numpy as np
import pytest
import torch
from helpers.cgnn_data import DENT_NAMES, dent_fold, write_dent_split, write_dent_states

import train.inference.predictor as predictor_module
from core.errors import BadInput
from train.inference.export import export_onnx
from train.inference.predictor import Predictor
from train.inference.si_model import SIModel, to_onnx
from train.model.cgnn import CGNN
from train.model.config import CGNNConfig
from train.model.knn import knn
from train.model.normalise import Envelope, Normaliser, highest_tip
from train.training.checkpoint import check_checkpoint, load_checkpoint
from train.training.migrate import migrate
from train.training.train_params import TrainInputs, TrainOptions, TrainParams
from train.training.train_stage import run_train

# a training envelope: presses of 1 to 5 mm from within 8 mm of the surface, tips down to -4 mm
ENVELOPE = Envelope(press_min=1e-3, press_max=5e-3, tip_lowest=-4e-3, gap_max=8e-3,
                    force_min=-100.0, force_max=100.0, top=0.5e-3)
NORM = Normaliser(centre=(0.05, 0.05, 0.0), scale=0.03, disp_scale=0.002, force_scale=1.0,
                  extent=0.08, envelope=ENVELOPE)
PRESS = np.array([0.05, 0.05, 0.001, 0.05, 0.05, -0.003], np.float32)
BACKENDS = ["torch", "onnx"]


# where the networks read the tip's offsets: nowhere (the paper's), the first layer, the heads
NETWORKS = {"paper": {}, "tip offsets": {"offsets": "graph"},
            "head offsets": {"offsets": "heads", "offset_width": 8}}


def _si(network: str, norm: Normaliser = NORM) -> SIModel:
    torch.manual_seed(1)
    return SIModel(CGNN(CGNNConfig(**NETWORKS[network])).eval(), norm)


def _grid(side: int) -> np.ndarray:
    """A regular ``side`` x ``side`` grid on 0.1 m x 0.1 m, z = 0 (the MSM's: ties everywhere)."""
    g = np.arange(side) / (side - 1) * 0.1
    return np.stack([*np.meshgrid(g, g), np.zeros((side, side))], -1).reshape(-1, 3) \
        .astype(np.float32)


def _lab() -> np.ndarray:
    """26 points as the lab's: a 5 x 5 marker grid 20 mm apart and one marker seen twice."""
    g = 0.01 + np.arange(5) * 0.02
    grid = np.stack([*np.meshgrid(g, g), np.zeros((5, 5))], -1).reshape(-1, 3)
    return np.concatenate([grid, grid[12:13]]).astype(np.float32)


def _ring() -> np.ndarray:
    """26 points with a tie wider than the first candidates: two rings of 12 about a centre,
    the centre and a point of the inner ring twice over (14 points 20 mm from the centre)."""
    a = np.arange(12) * np.pi / 6
    ring = [np.c_[0.05 + r * np.cos(a), 0.05 + r * np.sin(a), np.zeros(12)] for r in (0.02,
                                                                                      0.04)]
    return np.concatenate([*ring, [[0.05, 0.05, 0.0], [0.05, 0.07, 0.0]]]).astype(np.float32)


def _exported(si: SIModel) -> object:
    """An ONNX Runtime session of the exported graph (its own kNN in every layer)."""
    ort = pytest.importorskip("onnxruntime")
    buf = io.BytesIO()
    to_onnx(si, buf)
    return ort.InferenceSession(buf.getvalue(), providers=["CPUExecutionProvider"])


def _predictors(si: SIModel) -> dict[str, Predictor]:
    return {b: Predictor(si, torch.device("cpu"), b) for b in BACKENDS}


def _runs(si: SIModel, pts: np.ndarray, press: np.ndarray = PRESS,
          session: object | None = None, predictors: dict[str, Predictor] | None = None
          ) -> dict[str, tuple[np.ndarray, float]]:
    """The answer of each way a model runs: torch with its own kNN, the predictor on torch
    and on ONNX Runtime, and (given its session) the exported graph in ONNX Runtime."""
    with torch.no_grad():
        d, f = si(torch.from_numpy(pts)[None], torch.from_numpy(press)[None])
    out = {"torch": (d[0].numpy(), float(f[0]))}
    for b, p in (predictors or _predictors(si)).items():
        out[f"predictor {b}"] = p.predict(pts, press)
    if session is None:
        return out
    d, f = session.run(None, {"points": pts[None], "condition": press[None]})
    out["onnx export"] = (d[0], float(f[0]))
    return out


@pytest.mark.parametrize("network", list(NETWORKS))
@pytest.mark.parametrize("points", ["grid", "lab", "ring"])
def test_the_answer_does_not_depend_on_the_order_of_the_points(points: str, network: str
                                                               ) -> None:
    """5 orderings of a 32 x 32 grid (the MSM's), of 26 lab points, and of a wide tie. The
    exported graph cannot search again with more candidates: it is left out of the wide tie
    (the predictor builds the first layer's graph itself, in numpy)."""
    pts = {"grid": _grid(32), "lab": _lab(), "ring": _ring()}[points]
    si = _si(network)
    session, predictors = None if points == "ring" else _exported(si), _predictors(si)
    first = _runs(si, pts, session=session, predictors=predictors)
    rng = np.random.default_rng(5)
    for _ in range(5):
        perm = rng.permutation(len(pts))
        for name, (deformed, df) in _runs(si, pts[perm], session=session,
                                          predictors=predictors).items():
            np.testing.assert_allclose(deformed, first[name][0][perm], atol=1e-6, rtol=0,
                                       err_msg=name)
            assert df == pytest.approx(first[name][1], abs=1e-6), name


@pytest.mark.parametrize("network", list(NETWORKS))
def test_the_fewest_points_run_on_every_path(network: str) -> None:
    """k + 1 = 6 points, fewer than the exported graph's k + 2 candidates: the same answer."""
    pts = np.random.default_rng(0).uniform(0.04, 0.06, (6, 3)).astype(np.float32)
    si = _si(network)
    runs = _runs(si, pts, session=_exported(si))
    for name, (deformed, df) in runs.items():
        np.testing.assert_allclose(deformed, runs["torch"][0], atol=1e-6, err_msg=name)
        assert df == pytest.approx(runs["torch"][1], abs=1e-6), name


@pytest.mark.parametrize(("n", "f"), [(26, 3), (300, 64), (1500, 9)])
def test_knn_is_the_brute_force_nearest_where_there_are_no_ties(n: int, f: int) -> None:
    """Nearest first, in pieces or not; rows whose first six distances are not 1e-4 apart
    (relative: a near-tie, ranked by coordinates) are left out."""
    torch.manual_seed(n)
    x = torch.randn(2, n, f)
    d2, order = torch.cdist(x.double(), x.double()).square().sort(-1)
    gaps = (d2[..., 1:6] - d2[..., :5]) / d2[..., 1:6]
    clear = (gaps > 1e-4).all(-1)
    assert clear.float().mean() > 0.9
    assert (knn(x, 5) == order[..., :5])[clear].all()


@pytest.mark.parametrize("network", list(NETWORKS))
def test_a_tip_that_does_not_move_moves_nothing_and_changes_no_force(network: str) -> None:
    """C = [c, c] anywhere (on, above, below the surface) on every path: exactly nothing."""
    si, pts = _si(network), _grid(12)
    session, predictors = _exported(si), _predictors(si)
    for tip in ([0.05, 0.05, 0.0], [0.02, 0.07, 0.004], [0.05, 0.05, -0.045]):
        still = np.array(tip * 2, np.float32)
        for name, (deformed, df) in _runs(si, pts, still, session, predictors).items():
            np.testing.assert_array_equal(deformed, pts, err_msg=name)
            assert df == 0.0, name
        for p in predictors.values():
            assert p.predict_force(pts, still) == 0.0
            np.testing.assert_array_equal(p.predict(pts, still, region=0.02)[0], pts)
            assert p.predict_force(pts, still, region=0.02) == 0.0
            assert not p.extrapolating


def test_a_press_shorter_than_any_learned_shrinks_linearly() -> None:
    """Below a tenth of the shortest training press the answer is the network's times length
    / ramp (small-strain linearity); above it the network's own (training unchanged, and a
    held-out press a little shorter than the training ones too)."""
    pts = _grid(12)
    gated, bare = _si("paper"), _si("paper", replace(NORM, envelope=None))
    for length, share in ((0.025e-3, 0.25), (0.05e-3, 0.5), (0.1e-3, 1.0), (0.5e-3, 1.0),
                          (3e-3, 1.0)):
        press = np.r_[PRESS[:3], PRESS[:3] - [0, 0, length]].astype(np.float32)
        with torch.no_grad():
            d, f = gated(torch.from_numpy(pts)[None], torch.from_numpy(press)[None])
            d0, f0 = bare(torch.from_numpy(pts)[None], torch.from_numpy(press)[None])
        np.testing.assert_allclose(d.numpy() - pts, share * (d0.numpy() - pts), atol=1e-8)
        assert float(f) == pytest.approx(share * float(f0), rel=1e-6)


def _flags(p: Predictor, pts: np.ndarray, press: list[float]) -> str:
    """The warning a press gives ('' when none), checking ``extrapolating`` agrees."""
    with warnings.catch_warnings(record=True) as caught:
        warnings.simplefilter("always")
        p.predict(pts, np.array(press, np.float32))
    text = " ".join(str(w.message) for w in caught)
    assert p.extrapolating == bool(text)
    return text


@pytest.mark.parametrize("backend", BACKENDS)
def test_presses_beyond_the_training_envelope_are_flagged(backend: str) -> None:
    p, pts = Predictor(_si("tip offsets"), torch.device("cpu"), backend), _grid(12)
    assert _flags(p, pts, [0.05, 0.05, 0.001, 0.05, 0.05, -0.003]) == ""      # inside
    assert _flags(p, pts, [0.05, 0.05, 0.001] * 2) == ""                    # no motion: exact
    deep = _flags(p, pts, [0.05, 0.05, 0.001, 0.05, 0.05, -0.044])          # 45 mm down
    assert "longer than the longest learned (5 mm)" in deep
    assert "40 mm below the lowest learned" in deep
    assert "shorter than the shortest learned" in _flags(
        p, pts, [0.05, 0.05, 0.001, 0.05, 0.05, 0.000999])                    # 1 um
    assert "the tip start 20 mm above the surface" in _flags(
        p, pts, [0.0, 0.0, 0.02, 0.0, 0.0, 0.017])
    up = np.array([0, 0, 0.01], np.float32)                # the frame 10 mm off the surface
    assert "points up to 9.5 mm above the highest learned" in _flags(
        p, pts + up, [0.05, 0.05, 0.011, 0.05, 0.05, 0.007])
    p.norm = replace(NORM, envelope=replace(ENVELOPE, force_min=0.0, force_max=1e-6))
    assert "change of force" in _flags(p, pts, [0.05, 0.05, 0.001, 0.05, 0.05, -0.003])
    p.norm = replace(NORM, envelope=replace(ENVELOPE, force_min=0.5, force_max=2.5))
    assert _flags(p, pts, [0.05, 0.05, 0.001] * 2) == ""     # dF 0 is exact, not outside


def test_a_checkpoint_without_an_envelope_keeps_the_old_checks() -> None:
    """A checkpoint of a version that kept no envelope (read through the migration) has the
    distance checks alone."""
    old = {k: v for k, v in NORM.to_dict().items() if k != "envelope"}
    norm = Normaliser.from_dict(migrate({"norm": old})["norm"])
    assert norm.envelope is None and norm.to_dict()["envelope"] is None
    p, pts = Predictor(_si("paper", norm), torch.device("cpu"), "torch"), _grid(12)
    assert _flags(p, pts, [0.05, 0.05, 0.001, 0.05, 0.05, -0.044]) == ""
    assert p.predict(pts, np.array([0.05, 0.05, 0.001] * 2, np.float32))[1] == 0.0
    assert Normaliser.from_dict(NORM.to_dict()) == NORM


def test_the_envelope_is_what_the_training_examples_span() -> None:
    """Three examples on a flat 2 x 2 patch and the tip's own point (as the lab's): presses
    of 3 and 4 mm (and one of 0, left out of the shortest), the tip starting 1 and 2 mm
    above the patch's corners."""
    pts = np.zeros((3, 5, 3))
    pts[:, :4, :2] = [[0, 0], [0.01, 0], [0, 0.01], [0.01, 0.01]]
    cond = np.array([[0, 0, 0.001, 0, 0, -0.002], [0.01, 0.01, 0.002, 0.01, 0.01, -0.002],
                     [0, 0, 0.001, 0, 0, 0.001]])
    pts[:, 4] = cond[:, :3]
    env = Envelope.fit(cond, np.array([1.5, 2.0, -0.5]),
                       highest_tip(pts, np.ones((3, 5), bool), cond[:, :3]), 0.0)
    assert env == pytest.approx(Envelope(3e-3, 4e-3, -2e-3, 2e-3, -0.5, 2.0, 0.0))


def _state(norm: Normaliser) -> dict:
    cfg = CGNNConfig()
    return {"model": CGNN(cfg).state_dict(), "config": cfg.to_dict(), "norm": norm.to_dict(),
            "meta": {"options": {"fold": 0}, "config": {}, "data": {"file": "x"}, "splits": "s",
                     "init": None}}


def test_a_checkpoint_envelope_is_checked() -> None:
    check_checkpoint("c.pt", _state(NORM))
    check_checkpoint("c.pt", _state(replace(NORM, envelope=None)))
    bad = _state(NORM)
    bad["norm"]["envelope"]["press_max"] = float("nan")
    with pytest.raises(BadInput, match="envelope.press_max is nan"):
        check_checkpoint("c.pt", bad)
    bad["norm"]["envelope"]["press_max"] = 6.0           # millimetres written as metres
    with pytest.raises(BadInput, match="envelope.press_max is 6 m"):
        check_checkpoint("c.pt", bad)


@pytest.mark.parametrize("backend", BACKENDS)
def test_far_inputs_say_how_far_and_ask_about_millimetres_only_when_it_fits(backend: str
                                                                           ) -> None:
    p, pts = Predictor(_si("paper"), torch.device("cpu"), backend), _grid(12)
    with pytest.raises(ValueError, match="a point lies 17.4 m from the training data's "
                                         "centre") as shifted:
        p.predict(pts + 10.0, PRESS + 10.0)
    assert "millimetres" not in str(shifted.value)
    with pytest.raises(ValueError, match="the tip lies 17.3 m") as tip:
        p.predict(pts, PRESS + 10.0)
    assert "millimetres" not in str(tip.value)
    with pytest.raises(ValueError, match="m from the training data's centre.*millimetres"):
        p.predict(pts * 1000, PRESS * 1000)
    with pytest.raises(ValueError, match="the tip lies .*millimetres"):
        p.predict(pts, PRESS * 1000)


def test_large_scenes_build_their_graph_in_torch(monkeypatch) -> None:
    """Above ``LARGE`` points the calls that search neighbours run on the torch backend (its
    kNN works in pieces: memory linear in N), with the same answer."""
    pytest.importorskip("onnxruntime")
    si, pts = _si("tip offsets"), _grid(20)
    p = Predictor(si, torch.device("cpu"), "onnx")
    small = p.predict(pts, PRESS)
    used = []
    run = p.large.run
    monkeypatch.setattr(p.large, "run", lambda *a: used.append(a[0]) or run(*a))
    monkeypatch.setattr(predictor_module, "LARGE", 300)
    p._scene = None
    big = p.predict(pts, PRESS)
    assert used == ["full"]
    np.testing.assert_allclose(big[0], small[0], atol=1e-6)
    assert big[1] == pytest.approx(small[1], abs=1e-6)


@pytest.fixture(scope="module")
def dent_run(tmp_path_factory) -> Path:
    """A small model trained one epoch on the dent data."""
    d = tmp_path_factory.mktemp("dent_env")
    data, splits = dent_fold(d, folds=1)
    cfg = CGNNConfig(edge_widths=((16, 16),) * 3, disp_widths=(32,), force_widths=(16, 8, 8))
    run_train(TrainInputs(data, splits), d / "run",
              TrainParams(TrainOptions(epochs=1, batch=8), cfg, "cpu"))
    return d / "run"


def test_the_exported_graph_says_which_guards_it_lacks(dent_run: Path, tmp_path: Path) -> None:
    onnx = pytest.importorskip("onnx")
    ort = pytest.importorskip("onnxruntime")
    export_onnx(dent_run, tmp_path / "m.onnx")
    props = {p.key: p.value for p in onnx.load(str(tmp_path / "m.onnx")).metadata_props}
    assert {"units", "carried", "not_checked", "training_envelope"} <= set(props)
    assert json.loads(props["point_names"]) == DENT_NAMES      # the points it was trained on
    assert Predictor.load(dent_run).point_names == DENT_NAMES
    assert "NaN" in props["not_checked"] and "N^2" in props["not_checked"]
    norm = Normaliser.from_dict(load_checkpoint(dent_run / "best.pt")["norm"])
    env = json.loads(props["training_envelope"])
    assert env["extent"] == norm.extent and env["centre"] == list(norm.centre)
    pts = _grid(7) * 0.9 + 0.005
    still = np.array([0.05, 0.05, 0.0] * 2, np.float32)
    d, f = ort.InferenceSession(str(tmp_path / "m.onnx")).run(
        None, {"points": pts[None], "condition": still[None]})
    np.testing.assert_array_equal(d[0], pts)
    assert float(f[0]) == 0.0


def test_a_run_keeps_the_envelope_of_every_training_example(dent_run: Path,
                                                            tmp_path: Path) -> None:
    """The dent data press in 1 mm steps from the surface to 5 mm (single steps 1 mm, multi
    steps up to 5 mm), 0.5 N a step: the shortest press is 1 mm, the lowest tip 5 mm down.
    Fine-tuned (``--init``) on dent data of 3 steps, the envelope is that data's, and so is
    the whole normaliser: the one a run from scratch on the same data fits, not the
    pre-trained model's."""
    env_run = Normaliser.from_dict(load_checkpoint(dent_run / "best.pt")["norm"])
    env = env_run.envelope
    assert env.press_min == pytest.approx(1e-3, rel=1e-5)
    assert env.tip_lowest == pytest.approx(-5e-3, rel=1e-5)
    assert env.press_max == pytest.approx(5e-3, rel=1e-5)
    assert env.force_min == pytest.approx(0.5) and env.force_max == pytest.approx(2.5)
    assert env.top == pytest.approx(0.0, abs=1e-9)          # the rest surface, z = 0
    d = tmp_path / "few"
    d.mkdir()
    data, splits = d / "states.h5", d / "splits.json"
    write_dent_states(data, steps=3, seed=1)
    write_dent_split(data, splits)
    cfg = CGNNConfig(**load_checkpoint(dent_run / "best.pt")["config"])
    run_train(TrainInputs(data, splits, dent_run / "best.pt"), d / "tl",
              TrainParams(TrainOptions(epochs=1, batch=8), cfg, "cpu"))
    run_train(TrainInputs(data, splits), d / "scratch",
              TrainParams(TrainOptions(epochs=1, batch=8), cfg, "cpu"))
    tuned, scratch = (Normaliser.from_dict(load_checkpoint(d / r / "best.pt")["norm"])
                      for r in ("tl", "scratch"))
    assert tuned.envelope.tip_lowest == pytest.approx(-3e-3, rel=1e-5)
    assert tuned.disp_scale != pytest.approx(env_run.disp_scale, rel=1e-3)   # other data
    assert tuned == scratch

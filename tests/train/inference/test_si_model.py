"""The SI model's entries (:mod:`train.inference.si_model`): which a predictor of each network
runs, that the two-part runs (a scene, then presses on it) are the whole network in SI units,
and that each entry exports to an ONNX graph with the Entry's names that answers as torch does.

``test_head_split.py`` checks the split in the network's normalised units, and
``test_predictor.py`` the predictor's backends on trained runs; here the SI model itself is
held to its own ``forward`` (its normaliser and the no-motion gate included).
"""

from __future__ import annotations

import inspect
import io

import numpy as np
import pytest
import torch

from train.inference.si_model import (
    ENTRIES,
    PER_POINT,
    SIModel,
    entries,
    press_entries,
    to_onnx,
)
from train.model.cgnn import CGNN
from train.model.config import CGNNConfig
from train.model.normalise import Envelope, Normaliser

WIDTHS = {"edge_widths": ((8, 8),) * 3, "disp_widths": (16,), "force_widths": (8, 8, 8)}
NETWORKS = {"paper": {}, "noCond": {"use_condition": False}, "tip offsets": {"offsets": "graph"},
            "head offsets": {"offsets": "heads", "offset_width": 4}}
PRESS_INDEPENDENT = ["paper", "noCond", "head offsets"]
NORM = Normaliser((0.05, 0.05, 0.0), 0.03, disp_scale=0.002, force_scale=0.5, extent=0.08,
                  envelope=Envelope(1e-3, 5e-3, -4e-3, 8e-3, -1.0, 3.0, 0.5e-3))


def _si(network: str) -> SIModel:
    torch.manual_seed(0)
    return SIModel(CGNN(CGNNConfig(**WIDTHS, **NETWORKS[network])).eval(), NORM)


def _scene(n: int = 40, seed: int = 0) -> tuple[torch.Tensor, torch.Tensor]:
    """``n`` points on a gently curved 0.1 m patch (1, n, 3) and their 5 nearest (itself
    included), by brute force."""
    rng = np.random.default_rng(seed)
    xy = rng.uniform(0.0, 0.1, (n, 2))
    z = -0.002 * np.exp(-((xy - 0.05) ** 2).sum(1) / 0.001)
    points = torch.from_numpy(np.c_[xy, z].astype(np.float32))[None]
    return points, torch.cdist(points, points).topk(5, largest=False).indices


def _press(down: float = 3e-3, start_z: float = 1e-3) -> torch.Tensor:
    """C (1, 6): the tip from (0.05, 0.05, start_z) ``down`` metres down and 1 mm along x."""
    return torch.tensor([[0.05, 0.05, start_z, 0.051, 0.05, start_z - down]])


# --- which entries a predictor runs ----------------------------------------------------------

@pytest.mark.parametrize(("network", "want", "press"), [
    ("paper", ("new_scene", "pressed", "pressed", "pressed_force"),
     ("pressed", "pressed_force")),
    ("noCond", ("new_scene", "pressed", "pressed", "pressed_force"),
     ("pressed", "pressed_force")),
    ("head offsets", ("new_scene", "pressed", "pressed_surface", "pressed_force_surface"),
     ("pressed_surface", "pressed_force_surface")),
    ("tip offsets", ("full", "force"), None),
])
def test_each_network_runs_the_entries_its_offsets_allow(network: str, want: tuple,
                                                         press: tuple | None) -> None:
    """A press-independent network: a new scene, then presses on its cached terms (with head
    offsets reading the scene's points); tip offsets: the whole network every time."""
    si = _si(network)
    assert entries(si) == want
    if press is not None:
        assert press_entries(si) == press


@pytest.mark.parametrize("name", list(ENTRIES))
def test_an_entry_s_inputs_are_its_method_s_parameters_in_order(name: str) -> None:
    """An exporter passes the inputs positionally by the Entry's names: they must be the
    method's leading parameters, in its order; its outputs as many as it returns (run on the
    paper's network, or with head offsets where the entry reads the scene's points)."""
    entry = ENTRIES[name]
    params = list(inspect.signature(getattr(SIModel, entry.method)).parameters)[1:]
    assert params[:len(entry.inputs)] == list(entry.inputs)
    points, nb = _scene()
    si = _si("head offsets" if "surface" in entry.inputs else "paper")
    disp_terms, force_terms = si.scene(points, nb)
    made = {"points": points, "condition": _press(), "neighbours": nb, "surface": points,
            "disp_terms": disp_terms, "force_terms": force_terms}
    with torch.no_grad():
        out = getattr(si, entry.method)(*(made[i] for i in entry.inputs))
    assert len(out if isinstance(out, tuple) else (out,)) == len(entry.outputs)


# --- two parts equal the whole ---------------------------------------------------------------

@pytest.mark.parametrize("network", PRESS_INDEPENDENT)
def test_a_new_scene_and_its_presses_are_the_whole_network(network: str) -> None:
    """scene_and_press's answer, and ``pressed`` for two more presses on its cached terms,
    equal ``forward`` (each with its own kNN) within 1e-5 m and N; ``pressed_force`` and
    ``force`` the force alone."""
    si, (points, nb) = _si(network), _scene()
    surface = points if si.model.offsets.in_heads else None
    with torch.no_grad():
        disp_terms, force_terms, deformed, dforce = si.scene_and_press(points, nb, _press())
        ref_d, ref_f = si(points, _press())
        torch.testing.assert_close(deformed, ref_d, atol=1e-5, rtol=0)
        torch.testing.assert_close(dforce, ref_f, atol=1e-5, rtol=0)
        for c in (_press(1.5e-3), _press(4e-3, start_z=2e-3)):
            ref_d, ref_f = si(points, c)
            d, f = si.pressed(points, disp_terms, force_terms, c)
            torch.testing.assert_close(d, ref_d, atol=1e-5, rtol=0)
            torch.testing.assert_close(f, ref_f, atol=1e-5, rtol=0)
            torch.testing.assert_close(si.pressed_force(force_terms, c, surface), ref_f,
                                       atol=1e-5, rtol=0)
            torch.testing.assert_close(si.force(points, c), ref_f, atol=1e-5, rtol=0)
    assert not torch.equal(ref_d, points)         # the presses move the surface: a real test


@pytest.mark.parametrize("network", PRESS_INDEPENDENT)
def test_a_press_on_part_of_a_known_scene_is_the_whole_network_there(network: str) -> None:
    """Some of the scene's points, in order, with their terms (and with head offsets the
    whole scene as ``surface``): the whole network's answer on those points, its force."""
    si, (points, nb) = _si(network), _scene()
    some = torch.tensor([0, 3, 4, 17, 39])
    surface = points if si.model.offsets.in_heads else None
    with torch.no_grad():
        disp_terms, force_terms = si.scene(points, nb)
        ref_d, ref_f = si(points, _press())
        d, f = si.pressed(points[:, some], disp_terms[:, some], force_terms, _press(), surface)
    torch.testing.assert_close(d, ref_d[:, some], atol=1e-5, rtol=0)
    torch.testing.assert_close(f, ref_f, atol=1e-5, rtol=0)


@pytest.mark.parametrize("network", PRESS_INDEPENDENT)
def test_a_still_tip_on_a_known_scene_moves_nothing(network: str) -> None:
    """The no-motion gate is in the two-part runs too: C = [c, c] gives the points exactly and
    no force change."""
    si, (points, nb) = _si(network), _scene()
    still = _press(0.0)
    still[0, 3] = still[0, 0]
    surface = points if si.model.offsets.in_heads else None
    with torch.no_grad():
        disp_terms, force_terms = si.scene(points, nb)
        d, f = si.pressed(points, disp_terms, force_terms, still)
        assert torch.equal(d, points) and float(f) == 0.0
        assert float(si.pressed_force(force_terms, still, surface)) == 0.0


def test_pressed_force_of_a_heads_network_needs_the_scene_s_points() -> None:
    """Its force head pools every point's offsets from the tip: without ``surface`` there is
    nothing to pool, which is refused rather than answered wrongly."""
    si, (points, nb) = _si("head offsets"), _scene()
    with torch.no_grad():
        _, force_terms = si.scene(points, nb)
        with pytest.raises(ValueError, match="reads the scene's points per press"):
            si.pressed_force(force_terms, _press())
        si.pressed_force(force_terms, _press(), points)


# --- the ONNX graphs -------------------------------------------------------------------------

@pytest.mark.parametrize(("network", "entry"), [
    ("paper", "export"), ("paper", "new_scene"), ("paper", "pressed"),
    ("paper", "pressed_force"), ("head offsets", "pressed_surface"),
    ("head offsets", "pressed_force_surface"), ("tip offsets", "full"),
    ("tip offsets", "force"),
])
def test_an_exported_entry_has_the_entry_s_names_and_torch_s_answers(network: str,
                                                                    entry: str) -> None:
    """The graph's inputs and outputs are the Entry's, in order, their point axis dynamic
    ("N"; the scene's "M"); run in ONNX Runtime at another size than traced (the scene 40
    points, a region 12 of them) it answers as torch does, within 1e-5."""
    onnx = pytest.importorskip("onnx")
    ort = pytest.importorskip("onnxruntime")
    si, e = _si(network), ENTRIES[entry]
    buf = io.BytesIO()
    to_onnx(si, buf, entry, example_points=26)
    graph = onnx.load_from_string(buf.getvalue()).graph
    assert [i.name for i in graph.input] == list(e.inputs)
    assert [o.name for o in graph.output] == list(e.outputs)
    for value in (*graph.input, *graph.output):
        if value.name in PER_POINT:
            axis = value.type.tensor_type.shape.dim[1]
            assert axis.dim_param == ("M" if value.name == "surface" else "N"), value.name
    points, nb = _scene(40, seed=1)
    region = torch.arange(0, 40, 3)[:12]
    with torch.no_grad():
        disp_terms, force_terms = (si.scene(points, nb) if si.model.offsets.press_independent
                                   else (None, None))
        part = entry == "pressed_surface"
        made = {"points": points[:, region] if part else points, "condition": _press(),
                "neighbours": nb, "surface": points,
                "disp_terms": None if disp_terms is None else
                disp_terms[:, region] if part else disp_terms,
                "force_terms": force_terms}
        inputs = [made[name] for name in e.inputs]
        want = getattr(si, e.method)(*inputs)
    want = want if isinstance(want, tuple) else (want,)
    session = ort.InferenceSession(buf.getvalue(), providers=["CPUExecutionProvider"])
    got = session.run(None, {name: t.numpy() for name, t in zip(e.inputs, inputs,
                                                                 strict=True)})
    assert len(got) == len(want)
    for name, g, w in zip(e.outputs, got, want, strict=True):
        np.testing.assert_allclose(g, w.numpy(), atol=1e-5, rtol=0, err_msg=name)

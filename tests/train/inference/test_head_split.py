"""The predictor's split of each head's first layer gives the whole network's answer, and is
refused for a network it does not hold for."""

from __future__ import annotations

import pytest
import torch
from torch import nn

from train.inference.head_split import check_split, pressed_heads, scene_terms
from train.inference.predictor import Predictor
from train.inference.si_model import SIModel
from train.model.cgnn import CGNN
from train.model.config import CGNNConfig
from train.model.normalise import Normaliser

NORM = Normaliser((0.05, 0.05, 0.0), 0.04, 0.002, 0.5, 0.07)


def _model(**kw) -> CGNN:
    torch.manual_seed(0)
    return CGNN(CGNNConfig(**kw)).eval()


@pytest.mark.parametrize("kw", [{}, {"use_condition": False},
                                {"offsets": "heads", "offset_width": 16}])
def test_surface_terms_plus_the_press_are_the_whole_heads(kw: dict) -> None:
    """Per surface, each head's first layer without the press; per press, C's part (with
    head offsets also each point's offsets') and the rest: the plain heads' answer, with
    missing points left out of the pooling."""
    m = _model(**kw)
    x, c = torch.randn(2, 30, 3), torch.randn(2, 6)
    mask = torch.rand(2, 30) > 0.2
    with torch.no_grad():
        disp, force = m(x, c, mask)
        terms = scene_terms(m, m.features(x, None, mask), mask)
        split_disp, split_force = pressed_heads(m, terms, c, x, None, mask)  # x: the whole scene
        force_only = pressed_heads(m, scene_terms(m, m.features(x, None, mask), mask, False), c,
                                   None, x, mask)
    torch.testing.assert_close(split_disp, disp, atol=1e-5, rtol=1e-5)
    torch.testing.assert_close(split_force, force, atol=1e-5, rtol=1e-5)
    assert force_only[0] is None
    torch.testing.assert_close(force_only[1], force, atol=1e-5, rtol=1e-5)


def test_head_offsets_on_some_points_are_the_whole_heads_on_them() -> None:
    """A region: the displacement head on some points (their offsets, the whole surface's
    features) gives the whole network's answer there; the force is the whole surface's."""
    m = _model(offsets="heads", offset_width=16)
    x, c = torch.randn(1, 40, 3), torch.randn(1, 6)
    some = torch.tensor([3, 7, 8, 20, 39])
    with torch.no_grad():
        disp, force = m(x, c)
        terms = scene_terms(m, m.features(x, None))
        terms.disp = terms.disp[:, some]
        part, part_force = pressed_heads(m, terms, c, x[:, some], x)
    torch.testing.assert_close(part, disp[:, some], atol=1e-5, rtol=1e-5)
    torch.testing.assert_close(part_force, force, atol=1e-5, rtol=1e-5)


def test_head_offsets_read_where_each_point_is_relative_to_the_tip() -> None:
    """The heads' encoding reads each point's offsets from the tip (and their lengths):
    points and tip shifted together encode alike; a network without head offsets has none."""
    m = _model(offsets="heads", offset_width=16)
    x, c = torch.randn(1, 30, 3), torch.randn(1, 6)
    shift = torch.tensor([0.3, -0.2, 0.1])
    with torch.no_grad():
        enc = m.encoded(x, c)
        moved = m.encoded(x + shift, c + shift.repeat(2))
    assert enc.shape == (1, 30, 16)
    torch.testing.assert_close(moved, enc, atol=1e-5, rtol=1e-5)
    assert _model().encoded(x, c) is None


def test_a_head_that_does_not_start_with_a_linear_layer_is_refused() -> None:
    """A norm layer at the front of a head: its first layer's weight columns are not the
    head's, so the split (and a predictor that would cache it) refuses it."""
    m = _model()
    m.force_head = nn.Sequential(nn.LayerNorm(m.force_head[0].in_features), *m.force_head)
    with pytest.raises(ValueError, match="force_head does not start with a Linear layer"):
        check_split(m)
    si = SIModel(m, NORM)
    pts = torch.rand(1, 30, 3) * 0.1
    nb = torch.cdist(pts, pts).topk(5, largest=False).indices
    with pytest.raises(ValueError, match="Linear"):
        si.scene(pts, nb)
    with pytest.raises(ValueError, match="Linear"):
        Predictor(si, torch.device("cpu"), "torch")


def test_graph_layers_that_read_the_press_are_refused() -> None:
    with pytest.raises(ValueError, match="tip offsets"):
        check_split(_model(offsets="graph"))

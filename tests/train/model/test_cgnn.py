"""The cGNN as a whole: the same answer for any order and number of points, the heads' split
layer, the refusals (its edge convolution against PyG: test_edgeconv.py, its kNN: test_knn.py)."""

from __future__ import annotations

import pytest
import torch

from train.model.cgnn import CGNN
from train.model.config import CGNNConfig


def _model(**kw) -> CGNN:
    torch.manual_seed(0)
    return CGNN(CGNNConfig(**kw)).eval()


def test_displacement_follows_a_permutation_of_the_points() -> None:
    m = _model()
    x, c = torch.randn(2, 40, 3), torch.randn(2, 6)
    perm = torch.randperm(40)
    d, f = m(x, c)
    d2, f2 = m(x[:, perm], c)
    torch.testing.assert_close(d2, d[:, perm], atol=1e-5, rtol=1e-5)
    torch.testing.assert_close(f2, f, atol=1e-5, rtol=1e-5)


@pytest.mark.parametrize("n", [6, 26, 1024])
def test_any_number_of_points(n: int) -> None:
    d, f = _model()(torch.randn(1, n, 3), torch.randn(1, 6))
    assert d.shape == (1, n, 3) and f.shape == (1,)


def test_nocond_ignores_the_condition_and_cond_uses_it() -> None:
    x = torch.randn(1, 30, 3)
    c1, c2 = torch.randn(1, 6), torch.randn(1, 6)
    nc = _model(use_condition=False)
    torch.testing.assert_close(nc(x, c1), nc(x, c2))
    m = _model()
    assert not torch.allclose(m(x, c1)[1], m(x, c2)[1])


def test_force_only_path_equals_the_full_forward() -> None:
    m = _model()
    x, c = torch.randn(3, 26, 3), torch.randn(3, 6)
    torch.testing.assert_close(m.forward_force(x, c), m(x, c)[1])


def test_a_masked_point_does_not_change_the_others() -> None:
    m = _model()
    x, c = torch.randn(1, 26, 3), torch.randn(1, 6)
    mask = torch.ones(1, 26, dtype=torch.bool)
    mask[0, 3] = False
    d1, f1 = m(x, c, mask)
    x2 = x.clone()
    x2[0, 3] = 100.0
    d2, f2 = m(x2, c, mask)
    keep = mask[0]
    torch.testing.assert_close(d1[0, keep], d2[0, keep])
    torch.testing.assert_close(f1, f2)


@pytest.mark.parametrize("kw", [{}, {"offsets": "graph"}, {"use_condition": False}])
def test_heads_are_the_paper_heads_on_the_concatenated_input(kw: dict) -> None:
    """The heads are the paper's: each MLP on [features, C] (local: per point with C
    repeated; global: max and mean over the valid points, then C)."""
    m = _model(**kw)
    x, c = torch.randn(2, 30, 3), torch.randn(2, 6)
    mask = torch.rand(2, 30) > 0.2
    local = m.features(x, c, mask)
    pooled = [local.masked_fill(~mask[..., None], -torch.inf).amax(1),
              (local * mask[..., None]).sum(1) / mask.sum(1, keepdim=True)]
    if m.config.use_condition:
        local = torch.cat([local, c[:, None].expand(-1, 30, -1)], -1)
        pooled.append(c)
    disp, force = m(x, c, mask)
    torch.testing.assert_close(disp, m.disp_head(local), atol=1e-5, rtol=1e-5)
    torch.testing.assert_close(force, m.force_head(torch.cat(pooled, -1))[:, 0],
                               atol=1e-5, rtol=1e-5)


def test_the_conditioned_layer_refuses_features_of_another_width() -> None:
    """[features, C] passed beside C would add C twice: refused, never summed silently."""
    m = _model()
    x, c = torch.randn(2, 30, 3), torch.randn(2, 6)
    local = m.features(x, c)
    both = torch.cat([local, c[:, None].expand(-1, 30, -1)], -1)
    torch.testing.assert_close(m.disp_head[0](both), m.disp_head[0](local, c))
    with pytest.raises(ValueError, match="features before C"):
        m.disp_head[0](both, c)

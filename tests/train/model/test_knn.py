"""The kNN of the edge convolutions against known truth: the brute-force nearest points (by
sorting every distance) where nothing ties, in pieces past ``BLOCK`` and with masked points;
ties broken by the points' keys, never by their order; and the fast path (rows whose nearest
distances are apart take their sorted order, only rows where a tie can change the k nearest
or their order are ranked pairwise) against the full pairwise ranking of every row
(``choose`` on all of them), on random clouds (ties almost never) and on regular grids and
duplicates (ties everywhere)."""

from __future__ import annotations

import numpy as np
import pytest
import torch

import train.model.knn as knn_module
from train.inference.region import neighbour_table
from train.model.knn import BLOCK, choose, knn, tiebreak


def test_knn_is_the_nearest_points_itself_included() -> None:
    torch.manual_seed(1)
    x = torch.randn(1, 50, 3)
    idx = knn(x, 5)
    brute = torch.cdist(x, x).argsort(dim=-1)[..., :5]
    assert (idx.sort(-1).values == brute.sort(-1).values).all()
    assert (idx == torch.arange(50).view(1, 50, 1)).any(-1).all()


def test_knn_in_pieces_is_the_brute_force_nearest() -> None:
    """Past BLOCK distances the search runs in pieces (samples, then rows of one sample):
    the same neighbours as sorting every distance, masked points never chosen."""
    torch.manual_seed(2)
    n = 1100                                 # 2 x 1100^2 > BLOCK, and 1100 rows > BLOCK // n
    x = torch.randn(2, n, 16)
    mask = torch.rand(2, n) > 0.1
    assert 2 * n * n > BLOCK and n > BLOCK // n
    d = torch.cdist(x, x).masked_fill(~mask.unsqueeze(1), float("inf"))
    brute = d.argsort(dim=-1)[..., :5]
    assert (knn(x, 5, mask).sort(-1).values == brute.sort(-1).values).all()


def test_masked_points_are_never_neighbours() -> None:
    x = torch.randn(1, 20, 3)
    mask = torch.ones(1, 20, dtype=torch.bool)
    mask[0, :4] = False
    assert not torch.isin(knn(x, 5, mask), torch.arange(4)).any()


def _grid(side: int, batch: int = 1) -> torch.Tensor:
    """A regular ``side`` x ``side`` grid on 0.1 m x 0.1 m, z = 0, ``batch`` times."""
    g = torch.arange(side, dtype=torch.float32) / (side - 1) * 0.1
    x, y = torch.meshgrid(g, g, indexing="xy")
    return torch.stack([x, y, torch.zeros_like(x)], -1).reshape(1, -1, 3).repeat(batch, 1, 1)


def _full_rerank(monkeypatch: pytest.MonkeyPatch) -> None:
    """No row is apart: every row is ranked pairwise (the ranking before the fast path)."""
    monkeypatch.setattr(knn_module, "apart",
                        lambda d: torch.zeros(d.shape[:-1], dtype=torch.bool))


def _clouds() -> dict[str, tuple[torch.Tensor, torch.Tensor | None]]:
    torch.manual_seed(0)
    lab = _grid(5)[:, torch.arange(26) % 25]                    # a 5 x 5 grid, a point twice
    return {"26 random": (torch.rand(3, 26, 3), None),
            "1024 random in pieces": (torch.rand(2, 1024, 3), None),
            "64 features": (torch.randn(2, 300, 64), None),
            "masked": (torch.rand(4, 200, 3), torch.rand(4, 200) > 0.2),
            "32 x 32 grid": (_grid(32, 2), None),
            "grid and cloud": (torch.cat([_grid(16), torch.rand(1, 256, 3) * 0.1]), None),
            "duplicates": (lab, None),
            "grid, masked": (_grid(16, 2), torch.rand(2, 256) > 0.3)}


@pytest.mark.parametrize("name", list(_clouds()))
def test_the_fast_path_is_the_full_ranking(name: str, monkeypatch: pytest.MonkeyPatch) -> None:
    x, mask = _clouds()[name]
    fast = knn(x, 5, mask)
    _full_rerank(monkeypatch)
    assert torch.equal(fast, knn(x, 5, mask))


@pytest.mark.parametrize("grid", [False, True])
def test_the_first_layers_graph_is_the_full_ranking(grid: bool,
                                                    monkeypatch: pytest.MonkeyPatch) -> None:
    """The predictor's 3-D graph (a tree, then the kNN's ranking where distances tie)."""
    pts = (_grid(32)[0] if grid else torch.rand(1024, 3) * 0.1).numpy()
    fast = neighbour_table(pts, 5)
    _full_rerank(monkeypatch)
    np.testing.assert_array_equal(fast, neighbour_table(pts, 5))


def test_a_random_cloud_ranks_few_rows_pairwise(monkeypatch: pytest.MonkeyPatch) -> None:
    """The fast path is taken: on 2 x 1024 random points under 1 % of the rows are ranked
    pairwise; on a grid, where neighbours tie, every row is."""
    ranked_rows = []
    full = knn_module.choose

    def counted(dist: torch.Tensor, key: torch.Tensor, k: int) -> torch.Tensor:
        ranked_rows.append(dist[..., 0].numel())
        return full(dist, key, k)

    monkeypatch.setattr(knn_module, "choose", counted)
    torch.manual_seed(1)
    knn(torch.rand(2, 1024, 3), 5)
    assert sum(ranked_rows) < 0.01 * 2 * 1024
    ranked_rows.clear()
    knn(_grid(32), 5)
    assert sum(ranked_rows) >= 32 * 32


def test_a_tie_goes_to_the_smaller_key_whatever_the_order() -> None:
    """Two candidates at the same distance (up to rounding): the one with the smaller key
    comes first, in either order; one nearer by more than TIE comes before both."""
    dist = torch.tensor([[1.0, 1.0 + 1e-7, 0.5]])
    assert choose(dist, torch.tensor([[2.0, 1.0, 3.0]]), 3).tolist() == [[2, 1, 0]]
    assert choose(dist.flip(-1), torch.tensor([[3.0, 1.0, 2.0]]), 3).tolist() == [[0, 1, 2]]


def test_a_grids_points_have_keys_of_their_own() -> None:
    keys = tiebreak(_grid(32)[0])
    assert len(torch.unique(keys)) == 32 * 32

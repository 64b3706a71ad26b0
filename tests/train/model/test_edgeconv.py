"""The edge convolution computes what the paper's layer computes: PyTorch Geometric's
``EdgeConv(nn, aggr="mean")`` on the same weights and graph as the reference, and a point
left out of the graph (a missing marker) changes no other point's output."""

from __future__ import annotations

import pytest
import torch

from train.model.edgeconv import DynamicEdgeConv
from train.model.knn import knn


def _pyg_edge_index(idx: torch.Tensor) -> torch.Tensor:
    """Edges j -> i of a (B, N, k) neighbour table, nodes numbered across the batch."""
    b, n, k = idx.shape
    offset = (torch.arange(b) * n).view(b, 1, 1)
    src = (idx + offset).reshape(-1)
    dst = (torch.arange(n).view(1, n, 1).expand(b, n, k) + offset).reshape(-1)
    return torch.stack([src, dst])


@pytest.mark.parametrize("n", [6, 26, 300])
def test_edgeconv_matches_pytorch_geometric(n: int) -> None:
    pyg = pytest.importorskip("torch_geometric.nn")
    torch.manual_seed(n)
    layer = DynamicEdgeConv(3, 64, 64, k=5).double()
    peer = pyg.EdgeConv(layer.mlp, aggr="mean")    # shares (and re-initialises) layer.mlp
    x = torch.randn(2, n, 3, dtype=torch.float64)
    ours = layer(x)
    ref = peer(x.reshape(-1, 3), _pyg_edge_index(knn(x, 5)))
    torch.testing.assert_close(ours.reshape(-1, 64), ref, atol=1e-5, rtol=0)


def test_a_masked_point_changes_no_other_points_output() -> None:
    """A missing marker is never a neighbour: whatever its features, the others' outputs
    are the same, to the last bit."""
    torch.manual_seed(3)
    layer = DynamicEdgeConv(3, 16, 8, k=5)
    x = torch.rand(2, 40, 3)
    mask = torch.ones(2, 40, dtype=torch.bool)
    mask[:, 7] = False
    moved = x.clone()
    moved[:, 7] = torch.tensor([0.5, -0.2, 0.1])
    keep = mask.clone()
    assert torch.equal(layer(x, mask)[keep], layer(moved, mask)[keep])

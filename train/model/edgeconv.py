"""DynamicEdgeConv, dense and batched, in plain torch (the cGNN's graph layer).

For each point i the layer rebuilds a k-nearest-neighbour graph on its input features (the
point itself included, so k = 5 is the point and 4 others), sends each neighbour j the message
h(x_i, x_j - x_i) and averages the messages (paper, eq. 1, mean aggregation). h is a two-layer
MLP ``Linear(2F, H) -> ReLU -> Linear(H, O)``: exactly what PyTorch Geometric's
``EdgeConv(nn=layer.mlp, aggr="mean")`` computes (tests/train/model/test_cgnn.py checks it).

Two identities make it fast, with no change to the function:
- the first linear of h(x_i, x_j - x_i) is ``(Wa - Wb) x_i + Wb x_j + b``: both terms are
  computed once per point and only the H-wide ``Wb x_j`` is gathered per edge (as DGCNN does);
- the second linear commutes with the mean, so it runs once per point, not once per edge.

The neighbours are :func:`train.model.knn.knn`'s, whose ties are broken by the points
themselves, so the layer's output does not depend on the order of the points.
"""

from __future__ import annotations

from typing import cast

import torch
from torch import nn

from train.model.knn import knn


def gather_rows(x: torch.Tensor, idx: torch.Tensor) -> torch.Tensor:
    """Rows of ``x`` (B, N, H) at ``idx`` (B, Q, k): (B, Q, k, H).

    One ``index_select`` of whole rows on the flattened batch: quicker than ``gather`` with an
    expanded index, which reads the index once per feature."""
    b, q, k = idx.shape
    rows = idx + (torch.arange(b, device=idx.device) * x.shape[1]).view(b, 1, 1)
    return x.reshape(b * x.shape[1], -1).index_select(0, rows.reshape(-1)).reshape(b, q, k, -1)


class DynamicEdgeConv(nn.Module):
    """One dynamic edge convolution: kNN on the input features, mean of h(x_i, x_j - x_i)."""

    def __init__(self, in_features: int, hidden: int, out_features: int, k: int = 5) -> None:
        super().__init__()
        self.k = k
        self.mlp = nn.Sequential(nn.Linear(2 * in_features, hidden), nn.ReLU(),
                                 nn.Linear(hidden, out_features))

    def forward(self, x: torch.Tensor, mask: torch.Tensor | None = None,
                neighbours: torch.Tensor | None = None, key: torch.Tensor | None = None
                ) -> torch.Tensor:
        """Features (B, N, F) -> (B, N, O); ``neighbours`` (B, N, k), when the caller already
        knows the kNN of ``x`` (the first layer's, from 3-D points), skips the search; ``key``
        (B, N) breaks the search's ties (:func:`train.model.knn.knn`)."""
        first, second = cast(nn.Linear, self.mlp[0]), self.mlp[2]    # as __init__ builds them
        f = x.shape[-1]
        w_centre, w_offset = first.weight[:, :f], first.weight[:, f:]    # (H, F) each
        own = x @ (w_centre - w_offset).T + first.bias                    # (B, N, H)
        nbr = x @ w_offset.T                                               # (B, N, H)
        idx = knn(x, self.k, mask, key) if neighbours is None else neighbours  # (B, N, k)
        hidden = torch.relu(own.unsqueeze(2) + gather_rows(nbr, idx))      # (B, N, k, H)
        return second(hidden.mean(dim=2))                                  # (B, N, O)

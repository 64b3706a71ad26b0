"""The conditional graph neural network (cGNN) of the paper, on one screen.

points (B, N, 3) and condition C = [tip start, tip end] (B, 6), both normalised:
    x1 = EdgeConv(points), x2 = EdgeConv(x1), x3 = EdgeConv(x2)            (B, N, 64) each
    local  = [x1, x2, x3, C repeated per point]                           (B, N, 192 + 6)
    disp   = MLP 256-128-3 (local)                                        (B, N, 3)
    global = [max over points, mean over points] of [x1, x2, x3], C       (B, 384 + 6)
    dforce = MLP 128-64-32-1 (global): four linear layers                 (B,)
noCond (``use_condition=False``) removes C from both heads. Missing points (``mask`` False)
are never neighbours and never pooled. How a point moves depends mostly on where it is
relative to the tip, which the paper's network has to learn from absolute positions; ours may
be given each point's offsets from the tip (:class:`train.model.config.Offsets`):
- "graph": the first layer reads [p, p - c_start, p - c_end] (B, N, 9) (the follow-up cEGCL
  feeds the same);
- "heads": the graph layers stay press-independent, and each point's offsets and their
  lengths, r = [p - c_start, p - c_end, |p - c_start|, |p - c_end|] (B, N, 8), encoded per
  point as e = ReLU(Linear(8, W) r) (W = ``offset_width``), join the heads: the displacement
  head reads [x1, x2, x3, e, C], the force head [pooled x, max and mean of e, C].

The first layer's graph is the kNN of the points themselves (with "graph" offsets the distance of
two inputs is sqrt(3) times that of their points: the same neighbours). Every layer breaks a
tie between neighbours by the points' own coordinates (:func:`train.model.knn.knn`), so the
output does not depend on the order of the points, even on a regular grid. A caller that already
has it, for a mesh whose points do not change or from a 3-D tree, passes it as ``neighbours``.

The heads are MLPs on [features, C], as the paper draws them; their first layer
(:class:`ConditionedLinear`) adds C's part to the features' part instead of copying C to every
point. Unless the graph layers read the offsets, they never read C
(:attr:`train.model.config.Offsets.press_independent`), so a surface pressed again needs only
the heads: the predictor keeps each head's first part per surface and adds the press's
(:mod:`train.inference.head_split`); with "heads" offsets the press's part includes e's.
"""

from __future__ import annotations

from itertools import islice

import torch
from torch import nn

from train.model.config import CGNNConfig, Offsets
from train.model.edgeconv import DynamicEdgeConv
from train.model.knn import tiebreak

CONDITION = 6
OFFSET_INPUTS = 8     # a point's offsets from the tip's start and end, and their lengths


def mlp(widths: list[int]) -> nn.Sequential:
    """Linear layers of the given widths with ReLU between them (none after the last)."""
    layers: list[nn.Module] = []
    for i, (a, b) in enumerate(zip(widths[:-1], widths[1:], strict=True)):
        layers.append(nn.Linear(a, b))
        if i < len(widths) - 2:
            layers.append(nn.ReLU())
    return nn.Sequential(*layers)


class ConditionedLinear(nn.Linear):
    """A Linear layer on ``[x, e, C]``, C (B, 6) appended to every row of x (B, ..., F) and e
    (B, ..., E; the offsets' encoding, E = ``encoding``, 0 without), computed as
    ``(W_x x + b) + W_e e + W_C C`` so that the (B, N, F + E + 6) copy of C is never built. One
    weight, as an ``nn.Linear(F + E + 6, H)`` has: ``leading`` is the first part, ``press`` the
    rest, what the press changes."""

    def __init__(self, inputs: int, outputs: int, conditioned: bool, encoding: int = 0) -> None:
        super().__init__(inputs, outputs)
        self.conditioned, self.encoding = conditioned, encoding

    @property
    def features(self) -> int:
        """F: how many inputs come before e and C."""
        return self.in_features - self.encoding - (CONDITION if self.conditioned else 0)

    def leading(self, x: torch.Tensor) -> torch.Tensor:
        """``W_x x + b``: the part of the layer that the press does not change."""
        f = self.features
        if not torch.jit.is_tracing() and x.shape[-1] != f:   # C given twice, or features
            #                          of another network (a trace's widths are fixed)
            raise ValueError(f"the layer reads {f} features before C, not {x.shape[-1]}")
        return nn.functional.linear(x, self.weight[:, :f], self.bias)

    def press(self, part: torch.Tensor, cond: torch.Tensor | None,
              enc: torch.Tensor | None = None) -> torch.Tensor:
        """``part`` (B, ..., H) from :meth:`leading` with the press's part added: ``W_e e``
        (``enc`` (B, ..., E), where the layer reads one) and ``W_C C``."""
        if not self.conditioned:
            return part
        if cond is None:
            raise ValueError("the layer reads C: the press's condition is needed")
        if self.encoding:
            if enc is None:
                raise ValueError("the layer reads the offsets' encoding e: it is needed")
            f = self.features
            part = part + enc @ self.weight[:, f:f + self.encoding].T
        add = cond @ self.weight[:, -CONDITION:].T                          # (B, H)
        return part + add.view(add.shape[0], *[1] * (part.dim() - 2), -1)

    def forward(self, x: torch.Tensor, cond: torch.Tensor | None = None,
                enc: torch.Tensor | None = None) -> torch.Tensor:
        """On ``x``, ``enc`` and ``cond``; without ``cond``, a plain Linear on an ``x`` that
        holds them."""
        if cond is None:
            return super().forward(x)
        return self.press(self.leading(x), cond, enc)


class ConditionedMLP(nn.Sequential):
    """An MLP on ``[x, e, C]``: a :class:`ConditionedLinear`, then ReLU and Linear layers."""

    def __init__(self, widths: list[int], conditioned: bool, encoding: int = 0) -> None:
        first = ConditionedLinear(widths[0] + encoding + (CONDITION if conditioned else 0),
                                  widths[1], conditioned, encoding)  # built first: it draws first
        rest = [nn.ReLU(), *mlp(widths[1:])] if len(widths) > 2 else []
        super().__init__(first, *rest)

    def forward(self, x: torch.Tensor, cond: torch.Tensor | None = None,
                enc: torch.Tensor | None = None) -> torch.Tensor:
        return self.after_first(self[0](x, cond, enc))

    @property
    def first(self) -> ConditionedLinear:
        """The first layer, on ``[x, e, C]``."""
        layer = self[0]
        if not isinstance(layer, ConditionedLinear):
            raise TypeError(f"the head starts with a {type(layer).__name__}, not a "
                            "ConditionedLinear")
        return layer

    def after_first(self, x: torch.Tensor) -> torch.Tensor:
        """The layers after the first on its output."""
        for layer in islice(self, 1, None):
            x = layer(x)
        return x


class CGNN(nn.Module):
    """Predicts each point's displacement and the change of force (normalised units)."""

    def __init__(self, config: CGNNConfig | None = None) -> None:
        super().__init__()
        self.config = config = config or CGNNConfig()
        convs, channels = [], 9 if config.offsets is Offsets.GRAPH else 3
        for hidden, out in config.edge_widths:
            convs.append(DynamicEdgeConv(channels, hidden, out, config.k))
            channels = out
        self.convs = nn.ModuleList(convs)
        local, conditioned = sum(out for _, out in config.edge_widths), config.use_condition
        enc = config.offset_width if config.offsets.in_heads else 0
        self.disp_head = ConditionedMLP([local, *config.disp_widths, 3], conditioned, enc)
        self.force_head = ConditionedMLP([2 * local, *config.force_widths, 1], conditioned,
                                         2 * enc)
        self.encoder = nn.Linear(OFFSET_INPUTS, enc) if enc else None   # e, with "heads"

    @property
    def offsets(self) -> Offsets:
        """Where this network reads each point's offsets from the tip."""
        return self.config.offsets

    def inputs(self, points: torch.Tensor, cond: torch.Tensor | None) -> torch.Tensor:
        """The first layer's input: the points (B, N, 3), or with "graph" offsets
        [p, p - c_start, p - c_end] (B, N, 9)."""
        if self.offsets is not Offsets.GRAPH:
            return points
        if cond is None:
            raise ValueError("a network with graph offsets reads the press: cond is needed")
        tips = cond.reshape(-1, 1, 2, 3)
        return torch.cat([points, points - tips[:, :, 0], points - tips[:, :, 1]], dim=-1)

    def encoded(self, points: torch.Tensor, cond: torch.Tensor | None) -> torch.Tensor | None:
        """The heads' encoding of each point's offsets from the tip, e (B, N, W); None for a
        network that does not read them in its heads."""
        if self.encoder is None:
            return None
        if cond is None:
            raise ValueError("a network with head offsets reads the press: cond is needed")
        d = points.unsqueeze(2) - cond.reshape(-1, 1, 2, 3)             # (B, N, 2, 3)
        r = torch.cat([d.flatten(2), torch.linalg.vector_norm(d, dim=-1)], dim=-1)
        return torch.relu(self.encoder(r))

    def features(self, points: torch.Tensor, cond: torch.Tensor | None,
                 mask: torch.Tensor | None = None,
                 neighbours: torch.Tensor | None = None) -> torch.Tensor:
        """The three edge convolutions' outputs, concatenated (B, N, F) (``neighbours``: the
        points' kNN (B, N, k), if known; ``cond`` may be None when the offsets are
        ``press_independent``)."""
        x, outs, key = self.inputs(points, cond), [], tiebreak(points)   # key: ties' breaker
        for i, conv in enumerate(self.convs):
            x = torch.relu(conv(x, mask, neighbours if i == 0 else None, key))  # (B, N, O)
            outs.append(x)
        return torch.cat(outs, dim=-1)

    def force(self, local: torch.Tensor, cond: torch.Tensor | None,
              mask: torch.Tensor | None = None, enc: torch.Tensor | None = None
              ) -> torch.Tensor:
        """The force head (B,) on the pooled features, the pooled offsets' encoding (where
        the network has one) and C."""
        pooled = None if enc is None else pool(enc, mask)
        return self.force_head(pool(local, mask), cond, pooled).squeeze(-1)

    def heads(self, local: torch.Tensor, cond: torch.Tensor | None,
              mask: torch.Tensor | None = None, enc: torch.Tensor | None = None
              ) -> tuple[torch.Tensor, torch.Tensor]:
        """(displacement (B, N, 3), change of force (B,)) from the features (B, N, F) and
        the offsets' encoding (B, N, W) or None."""
        force = self.force(local, cond, mask, enc)     # first: backward then sums the
        return self.disp_head(local, cond, enc), force  # gradients in one fixed order

    def forward(self, points: torch.Tensor, cond: torch.Tensor,
                mask: torch.Tensor | None = None, neighbours: torch.Tensor | None = None
                ) -> tuple[torch.Tensor, torch.Tensor]:
        """(displacement (B, N, 3), change of force (B,)), normalised."""
        return self.heads(self.features(points, cond, mask, neighbours), cond, mask,
                          self.encoded(points, cond))

    def forward_force(self, points: torch.Tensor, cond: torch.Tensor,
                      mask: torch.Tensor | None = None,
                      neighbours: torch.Tensor | None = None) -> torch.Tensor:
        """Only the change of force (B,): the displacement head is skipped."""
        return self.force(self.features(points, cond, mask, neighbours), cond, mask,
                          self.encoded(points, cond))


def pool(local: torch.Tensor, mask: torch.Tensor | None) -> torch.Tensor:
    """[max, mean] over the valid points of the features (B, N, F): (B, 2F)."""
    if mask is None:
        return torch.cat([local.amax(dim=1), local.mean(dim=1)], dim=-1)
    m = mask.unsqueeze(-1)
    count = m.sum(dim=1).clamp(min=1)
    return torch.cat([local.masked_fill(~m, float("-inf")).amax(dim=1),
                      local.masked_fill(~m, 0.0).sum(dim=1) / count], dim=-1)

"""The conditional graph neural network (cGNN) of the paper, on one screen.

points (B, N, 3) and condition C = [tip start, tip end] (B, 6), both normalised:
    x1 = EdgeConv(points), x2 = EdgeConv(x1), x3 = EdgeConv(x2)            (B, N, 64) each
    local  = [x1, x2, x3, C repeated per point]                           (B, N, 192 + 6)
    disp   = MLP 256-128-3 (local)                                        (B, N, 3)
    global = [max over points, mean over points] of [x1, x2, x3], C       (B, 384 + 6)
    dforce = MLP 128-64-32-1 (global): four linear layers                 (B,)
noCond (``use_condition=False``) removes C from both heads. Missing points (``mask`` False)
are never neighbours and never pooled. ``tip_offsets`` (ours, not the paper's) also gives the
first layer each point's offset from the tip's start and end, [p, p - c_start, p - c_end]
(B, N, 9): how a point moves depends mostly on where it is relative to the tip, which the
paper's network has to learn from absolute positions (the follow-up cEGCL feeds the same).
``head_offsets`` W (ours) gives the same to the heads instead, so the graph layers stay
press-independent: each point's offsets from the tip's start and end and their lengths,
r = [p - c_start, p - c_end, |p - c_start|, |p - c_end|] (B, N, 8), encoded per point as
e = ReLU(Linear(8, W) r), join the heads: the displacement head reads [x1, x2, x3, e, C], the
force head [pooled x, max and mean of e over the points, C].

The first layer's graph is the kNN of the points themselves (with tip offsets the distance of
two inputs is sqrt(3) times that of their points: the same neighbours). Every layer breaks a
tie between neighbours by the points' own coordinates (:func:`train.edgeconv.knn`), so the
output does not depend on the order of the points, even on a regular grid. A caller that already
has it, for a mesh whose points do not change or from a 3-D tree, passes it as ``neighbours``.

The heads are MLPs on [features, C], as the paper draws them; their first layer
(:class:`ConditionedLinear`) adds C's part to the features' part instead of copying C to every
point. Without tip offsets the graph layers never read C (``press_independent``), so a surface
pressed again needs only the heads: the predictor keeps each head's first part per surface and
adds the press's (:mod:`train.head_split`); with head offsets the press's part includes e's.
"""

from __future__ import annotations

from dataclasses import asdict, dataclass
from itertools import islice
from typing import Any

import torch
from torch import nn

from train.edgeconv import DynamicEdgeConv, tiebreak
from train.paper import K as PAPER_K

CONDITION = 6
OFFSETS = 8               # a point's offsets from the tip's start and end, and their lengths


@dataclass(frozen=True)
class CGNNConfig:
    """Widths of the network (the paper gives none; these are ours) and its variant."""

    k: int = PAPER_K
    edge_widths: tuple[tuple[int, int], ...] = ((64, 64), (64, 64), (64, 64))
    disp_widths: tuple[int, ...] = (256, 128)
    force_widths: tuple[int, ...] = (128, 64, 32)
    use_condition: bool = True
    tip_offsets: bool = False
    head_offsets: int = 0      # the width W of the heads' offset encoding e (0: none)

    def __post_init__(self) -> None:
        if (self.tip_offsets or self.head_offsets) and not self.use_condition:
            raise ValueError("tip offsets are the condition C: noCond cannot have them")
        if self.tip_offsets and self.head_offsets:
            raise ValueError("tip offsets in the first layer or in the heads, not both")
        if self.head_offsets < 0:
            raise ValueError(f"head offsets' width must be >= 0, got {self.head_offsets}")

    def to_dict(self) -> dict[str, Any]:
        """Plain types, for a checkpoint loaded with ``weights_only``."""
        d = asdict(self)
        d["edge_widths"] = [list(w) for w in self.edge_widths]
        d["disp_widths"], d["force_widths"] = list(self.disp_widths), list(self.force_widths)
        return d

    @classmethod
    def from_dict(cls, d: dict[str, Any]) -> CGNNConfig:
        return cls(k=int(d["k"]), edge_widths=tuple(tuple(w) for w in d["edge_widths"]),
                   disp_widths=tuple(d["disp_widths"]), force_widths=tuple(d["force_widths"]),
                   use_condition=bool(d["use_condition"]),
                   tip_offsets=bool(d.get("tip_offsets", False)),
                   head_offsets=int(d.get("head_offsets", 0)))


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
    (B, ..., E; the head offsets' encoding, E = ``offsets``, 0 without), computed as
    ``(W_x x + b) + W_e e + W_C C`` so that the (B, N, F + E + 6) copy of C is never built. One
    weight, as an ``nn.Linear(F + E + 6, H)`` has: ``leading`` is the first part, ``press`` the
    rest, what the press changes."""

    def __init__(self, inputs: int, outputs: int, conditioned: bool, offsets: int = 0) -> None:
        super().__init__(inputs, outputs)
        self.conditioned, self.offsets = conditioned, offsets

    @property
    def width(self) -> int:
        """F: how many inputs come before e and C."""
        return self.in_features - self.offsets - (CONDITION if self.conditioned else 0)

    def leading(self, x: torch.Tensor) -> torch.Tensor:
        """``W_x x + b``: the part of the layer that the press does not change."""
        width = self.width
        if not torch.jit.is_tracing() and x.shape[-1] != width:   # C given twice, or
            #                      features of another network (a trace's widths are fixed)
            raise ValueError(f"the layer reads {width} features before C, not {x.shape[-1]}")
        return nn.functional.linear(x, self.weight[:, :width], self.bias)

    def press(self, part: torch.Tensor, cond: torch.Tensor | None,
              enc: torch.Tensor | None = None) -> torch.Tensor:
        """``part`` (B, ..., H) from :meth:`leading` with the press's part added: ``W_e e``
        (``enc`` (B, ..., E), where the layer reads one) and ``W_C C``."""
        if not self.conditioned:
            return part
        if self.offsets:
            part = part + enc @ self.weight[:, self.width:self.width + self.offsets].T
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

    def __init__(self, widths: list[int], conditioned: bool, offsets: int = 0) -> None:
        first = ConditionedLinear(widths[0] + offsets + (CONDITION if conditioned else 0),
                                  widths[1], conditioned, offsets)  # made first: seed's order
        rest = [nn.ReLU(), *mlp(widths[1:])] if len(widths) > 2 else []
        super().__init__(first, *rest)

    def forward(self, x: torch.Tensor, cond: torch.Tensor | None = None,
                enc: torch.Tensor | None = None) -> torch.Tensor:
        return self.after_first(self[0](x, cond, enc))

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
        convs, width = [], 9 if config.tip_offsets else 3
        for hidden, out in config.edge_widths:
            convs.append(DynamicEdgeConv(width, hidden, out, config.k))
            width = out
        self.convs = nn.ModuleList(convs)
        local, conditioned = sum(out for _, out in config.edge_widths), config.use_condition
        width = config.head_offsets
        self.disp_head = ConditionedMLP([local, *config.disp_widths, 3], conditioned, width)
        self.force_head = ConditionedMLP([2 * local, *config.force_widths, 1], conditioned,
                                         2 * width)
        self.offsets = nn.Linear(OFFSETS, width) if width else None

    def inputs(self, points: torch.Tensor, cond: torch.Tensor | None) -> torch.Tensor:
        """The first layer's input: the points (B, N, 3), or with tip offsets
        [p, p - c_start, p - c_end] (B, N, 9)."""
        if not self.config.tip_offsets:
            return points
        tips = cond.reshape(-1, 1, 2, 3)
        return torch.cat([points, points - tips[:, :, 0], points - tips[:, :, 1]], dim=-1)

    def encoded(self, points: torch.Tensor, cond: torch.Tensor | None) -> torch.Tensor | None:
        """The heads' encoding of each point's offsets from the tip, e (B, N, W); None for a
        network without head offsets."""
        if self.offsets is None:
            return None
        d = points.unsqueeze(2) - cond.reshape(-1, 1, 2, 3)             # (B, N, 2, 3)
        r = torch.cat([d.flatten(2), torch.linalg.vector_norm(d, dim=-1)], dim=-1)
        return torch.relu(self.offsets(r))

    def features(self, points: torch.Tensor, cond: torch.Tensor | None,
                 mask: torch.Tensor | None = None,
                 neighbours: torch.Tensor | None = None) -> torch.Tensor:
        """The three edge convolutions' outputs, concatenated (B, N, F) (``neighbours``: the
        points' kNN (B, N, k), if known; ``cond`` may be None when ``press_independent``)."""
        x, outs, key = self.inputs(points, cond), [], tiebreak(points)   # key: ties' breaker
        for i, conv in enumerate(self.convs):
            x = torch.relu(conv(x, mask, neighbours if i == 0 else None, key))  # (B, N, O)
            outs.append(x)
        return torch.cat(outs, dim=-1)

    @property
    def press_independent(self) -> bool:
        """True when the graph layers never read C (without tip offsets: the paper's network,
        or head offsets): a surface's features are then the same for every press, and a
        caller pressing one surface again computes them once (:mod:`train.head_split`)."""
        return not self.config.tip_offsets

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
        force = self.force(local, cond, mask, enc)     # first: the gradients then sum in the
        return self.disp_head(local, cond, enc), force  # order they always had (bit-alike)

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

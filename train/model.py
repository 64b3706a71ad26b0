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

The first layer's graph is the kNN of the points themselves (with tip offsets the distance of
two inputs is sqrt(3) times that of their points: the same neighbours). Every layer breaks a
tie between neighbours by the points' own coordinates (:func:`train.edgeconv.knn`), so the
output does not depend on the order of the points, even on a regular grid. A caller that already
has it, for a mesh whose points do not change or from a 3-D tree, passes it as ``neighbours``.

Each head's first layer is split in two, ``W [features, C] + b = (W_f features + b) + W_C C``
(:meth:`CGNN.scene_terms`, then :meth:`CGNN.heads`): the same function, with no per-point copy
of C; and without tip offsets the first part does not depend on the press, so a surface pressed
again needs only the second (``press_independent``; :class:`train.Predictor` caches it).
"""

from __future__ import annotations

from dataclasses import asdict, dataclass, field
from itertools import islice
from typing import Any

import torch
from torch import nn

from train.edgeconv import DynamicEdgeConv, tiebreak

CONDITION = 6


@dataclass(frozen=True)
class CGNNConfig:
    """Widths of the network (the paper gives none; these are ours) and its variant."""

    k: int = 5
    edge_widths: tuple[tuple[int, int], ...] = ((64, 64), (64, 64), (64, 64))
    disp_widths: tuple[int, ...] = (256, 128)
    force_widths: tuple[int, ...] = (128, 64, 32)
    use_condition: bool = True
    tip_offsets: bool = False

    def __post_init__(self) -> None:
        if self.tip_offsets and not self.use_condition:
            raise ValueError("tip offsets are the condition C: noCond cannot have them")

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
                   tip_offsets=bool(d.get("tip_offsets", False)))


def mlp(widths: list[int]) -> nn.Sequential:
    """Linear layers of the given widths with ReLU between them (none after the last)."""
    layers: list[nn.Module] = []
    for i, (a, b) in enumerate(zip(widths[:-1], widths[1:], strict=True)):
        layers.append(nn.Linear(a, b))
        if i < len(widths) - 2:
            layers.append(nn.ReLU())
    return nn.Sequential(*layers)


@dataclass
class Features:
    """The layers' outputs a head reads: local features, the condition, the valid points."""

    local: torch.Tensor                  # (B, N, F) concatenated layer outputs
    cond: torch.Tensor | None            # (B, 6) or None (noCond)
    mask: torch.Tensor | None = field(default=None)


@dataclass
class HeadTerms:
    """What a surface gives each head's first layer before the press is added: (B, N, H) for
    the displacement head (None when only the force is asked), (B, H) for the force head."""

    disp: torch.Tensor | None
    force: torch.Tensor


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
        local = sum(out for _, out in config.edge_widths)
        cond = CONDITION if config.use_condition else 0
        self.disp_head = mlp([local + cond, *config.disp_widths, 3])
        self.force_head = mlp([2 * local + cond, *config.force_widths, 1])

    def inputs(self, points: torch.Tensor, cond: torch.Tensor | None) -> torch.Tensor:
        """The first layer's input: the points (B, N, 3), or with tip offsets
        [p, p - c_start, p - c_end] (B, N, 9)."""
        if not self.config.tip_offsets:
            return points
        tips = cond.reshape(-1, 1, 2, 3)
        return torch.cat([points, points - tips[:, :, 0], points - tips[:, :, 1]], dim=-1)

    def features(self, points: torch.Tensor, cond: torch.Tensor | None,
                 mask: torch.Tensor | None = None,
                 neighbours: torch.Tensor | None = None) -> Features:
        """The three edge convolutions' outputs, concatenated (``neighbours``: the points'
        kNN (B, N, k), if known; ``cond`` may be None when ``press_independent``)."""
        x, outs, key = self.inputs(points, cond), [], tiebreak(points)   # key: ties' breaker
        for i, conv in enumerate(self.convs):
            x = torch.relu(conv(x, mask, neighbours if i == 0 else None, key))  # (B, N, O)
            outs.append(x)
        return Features(torch.cat(outs, dim=-1),
                         cond if self.config.use_condition else None, mask)

    @property
    def press_independent(self) -> bool:
        """True when the graph layers never read C (the paper's network, without tip
        offsets): a surface's features are then the same for every press, and a caller
        pressing one surface again computes them once (:meth:`scene_terms`)."""
        return not self.config.tip_offsets

    def scene_terms(self, f: Features, displacement: bool = True) -> HeadTerms:
        """Each head's first linear layer on what the press does not change (bias in): the
        local features, and the max- and mean-pooled ones. ``displacement=False``: force only."""
        x = f.local
        if f.mask is None:
            pooled = [x.amax(dim=1), x.mean(dim=1)]
        else:
            m = f.mask.unsqueeze(-1)
            count = m.sum(dim=1).clamp(min=1)
            pooled = [x.masked_fill(~m, float("-inf")).amax(dim=1),
                      x.masked_fill(~m, 0.0).sum(dim=1) / count]
        g = torch.cat(pooled, dim=-1)
        return HeadTerms(_leading(self.disp_head[0], x) if displacement else None,
                         _leading(self.force_head[0], g))

    def heads(self, terms: HeadTerms, cond: torch.Tensor | None
              ) -> tuple[torch.Tensor | None, torch.Tensor]:
        """(displacement (B, N, 3) or None, change of force (B,)): C's part of each head's
        first layer added to the scene's, then the rest of the head."""
        force = _rest(self.force_head, self._add_press(self.force_head[0], terms.force, cond))
        if terms.disp is None:
            return None, force.squeeze(-1)
        disp = _rest(self.disp_head, self._add_press(self.disp_head[0], terms.disp, cond))
        return disp, force.squeeze(-1)

    def _add_press(self, first: nn.Linear, scene: torch.Tensor, cond: torch.Tensor | None
                 ) -> torch.Tensor:
        """``first([features, C])`` from ``scene`` = its features' part: adds C's part."""
        if cond is None or not self.config.use_condition:
            return scene
        press = cond @ first.weight[:, -CONDITION:].T                        # (B, H)
        return scene + press.view(press.shape[0], *[1] * (scene.dim() - 2), -1)

    def forward(self, points: torch.Tensor, cond: torch.Tensor,
                mask: torch.Tensor | None = None, neighbours: torch.Tensor | None = None
                ) -> tuple[torch.Tensor, torch.Tensor]:
        """(displacement (B, N, 3), change of force (B,)), normalised."""
        f = self.features(points, cond, mask, neighbours)
        return self.heads(self.scene_terms(f), f.cond)

    def forward_force(self, points: torch.Tensor, cond: torch.Tensor,
                      mask: torch.Tensor | None = None,
                      neighbours: torch.Tensor | None = None) -> torch.Tensor:
        """Only the change of force (B,): the displacement head is skipped."""
        f = self.features(points, cond, mask, neighbours)
        return self.heads(self.scene_terms(f, displacement=False), f.cond)[1]


def _rest(head: nn.Sequential, x: torch.Tensor) -> torch.Tensor:
    """``head`` after its first layer."""
    for layer in islice(head, 1, None):
        x = layer(x)
    return x


def _leading(first: nn.Linear, x: torch.Tensor) -> torch.Tensor:
    """``first`` on the leading ``x.shape[-1]`` inputs of its own (bias in, C's columns left
    out): the head's input ``[x, C]`` is never built, so no (B, N, F + 6) copy is made."""
    return nn.functional.linear(x, first.weight[:, :x.shape[-1]], first.bias)

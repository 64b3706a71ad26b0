"""The predictor's cache of a surface: each head's first layer split into the surface's part and
the press's, for a network whose graph layers never read the press.

A head's first layer on ``[features, C]`` is ``W [features, C] + b = (W_f features + b) + W_C
C``. Where the graph layers do not read the offsets
(:attr:`train.model.config.Offsets.press_independent`) the features do not depend on the
press, so a surface pressed again keeps the first part (its head terms: :func:`scene_terms`,
once per surface) and adds only C's part before the rest of each head (:func:`pressed_heads`,
per press): the network's answer, at a fraction of the time, and no per-point copy of C. A
network with offsets in its heads (:attr:`train.model.config.Offsets.in_heads`) also adds, per
press, its first layers' part of each point's offset encoding: the displacement head's on the
points it moves, the force head's pooled over the whole surface. The split reads the first
layer's weight columns, so it holds only for a head that starts with a Linear layer on
``[features, C]``; any other head is refused (:func:`check_split`), never silently
mis-split. The SI model's ``scene``, ``pressed`` and ``pressed_force`` entries
(:class:`train.inference.si_model.SIModel`) run these.
"""

from __future__ import annotations

from dataclasses import dataclass

import torch

from train.model.cgnn import CGNN, ConditionedLinear, ConditionedMLP, pool


@dataclass
class HeadTerms:
    """What a surface gives each head's first layer before the press is added: (B, N, H) for
    the displacement head (None when only the force is asked), (B, H) for the force head."""

    disp: torch.Tensor | None
    force: torch.Tensor


def check_split(model: CGNN) -> None:
    """Refuse (ValueError) a model the split does not hold for: graph layers that read the
    press (tip offsets), or a head that does not start with a :class:`ConditionedLinear`."""
    if not model.offsets.press_independent:
        raise ValueError("this model's graph layers read the press (tip offsets): "
                         "a surface's features are not the same for every press")
    for name in ("disp_head", "force_head"):
        head = getattr(model, name)
        if not isinstance(head, ConditionedMLP) or not isinstance(head[0], ConditionedLinear):
            raise ValueError(f"{name} does not start with a Linear layer on [features, C]: "
                             "its first layer cannot be split into the surface's part and "
                             "the press's")


def scene_terms(model: CGNN, local: torch.Tensor, mask: torch.Tensor | None = None,
                displacement: bool = True) -> HeadTerms:
    """Each head's first layer on what the press does not change (bias in): the features
    (B, N, F), and their max- and mean-pooled ones. ``displacement=False``: force only."""
    check_split(model)
    return HeadTerms(model.disp_head.first.leading(local) if displacement else None,
                     model.force_head.first.leading(pool(local, mask)))


def pressed_heads(model: CGNN, terms: HeadTerms, cond: torch.Tensor,
                  points: torch.Tensor | None = None, surface: torch.Tensor | None = None,
                  mask: torch.Tensor | None = None) -> tuple[torch.Tensor | None, torch.Tensor]:
    """(displacement (B, n, 3) or None, change of force (B,)): the press's part of each head's
    first layer added to the surface's terms, then the rest of the head. ``terms`` come from
    :func:`scene_terms`, which checked the model: nothing is checked here, per press. With
    head offsets the press's part reads ``points`` (B, n, 3), those of ``terms.disp``, and the
    force head pools the offsets of ``surface`` (B, N, 3), every point of the scene, or of
    ``points`` where ``surface`` is None (they are the whole scene); normalised, as ``cond``
    is. ``mask``: the scene's valid points, as :func:`scene_terms` was given them."""
    enc = model.encoded(points, cond) if points is not None else None
    pooled = None
    if model.offsets.in_heads:
        offsets = model.encoded(surface, cond) if surface is not None else enc
        if offsets is None:
            raise ValueError("a network with head offsets reads the scene's points per press")
        pooled = pool(offsets, mask)
    force = _after(model.force_head, terms.force, cond, pooled)
    if terms.disp is None:
        return None, force.squeeze(-1)
    return _after(model.disp_head, terms.disp, cond, enc), force.squeeze(-1)


def _after(head: ConditionedMLP, part: torch.Tensor, cond: torch.Tensor,
           enc: torch.Tensor | None) -> torch.Tensor:
    """The head's output from its first layer's surface part: the press's part added, then
    the rest."""
    return head.after_first(head.first.press(part, cond, enc))

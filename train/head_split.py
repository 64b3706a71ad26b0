"""The predictor's cache of a surface: each head's first layer split into the surface's part
and the press's, for a network whose graph layers never read the press.

A head's first layer on ``[features, C]`` is ``W [features, C] + b = (W_f features + b) +
W_C C``. Without tip offsets (:attr:`train.model.CGNN.press_independent`) the features do not
depend on the press, so a surface pressed again keeps the first part (its head terms:
:func:`scene_terms`, once per surface) and adds only C's part before the rest of each head
(:func:`pressed_heads`, per press): the network's answer, at a fraction of the time, and no
per-point copy of C. The split reads the first layer's weight columns, so it holds only for a
head that starts with a Linear layer on ``[features, C]``; any other head is refused
(:func:`check_split`), never silently mis-split. The SI model's ``scene``, ``pressed`` and
``pressed_force`` entries (:class:`train.si_model.SIModel`) run these.
"""

from __future__ import annotations

from dataclasses import dataclass
from itertools import islice

import torch
from torch import nn

from train.model import CGNN, CONDITION, pool


@dataclass
class HeadTerms:
    """What a surface gives each head's first layer before the press is added: (B, N, H) for
    the displacement head (None when only the force is asked), (B, H) for the force head."""

    disp: torch.Tensor | None
    force: torch.Tensor


def check_split(model: CGNN) -> None:
    """Refuse (ValueError) a model the split does not hold for: graph layers that read the
    press (tip offsets), or a head that does not start with a Linear layer."""
    if not model.press_independent:
        raise ValueError("this model's graph layers read the press (tip offsets): "
                         "a surface's features are not the same for every press")
    local = sum(out for _, out in model.config.edge_widths)
    cond = CONDITION if model.config.use_condition else 0
    for name, width in (("disp_head", local + cond), ("force_head", 2 * local + cond)):
        head = getattr(model, name)
        if not isinstance(head, nn.Sequential) or not isinstance(head[0], nn.Linear):
            raise ValueError(f"{name} does not start with a Linear layer: its first layer "
                             "cannot be split into the surface's part and the press's")
        if head[0].in_features != width:
            raise ValueError(f"{name}'s first layer reads {head[0].in_features} inputs, not "
                             f"the features and C ({width}): it cannot be split")


def scene_terms(model: CGNN, local: torch.Tensor, mask: torch.Tensor | None = None,
                displacement: bool = True) -> HeadTerms:
    """Each head's first layer on what the press does not change (bias in): the features
    (B, N, F), and their max- and mean-pooled ones. ``displacement=False``: force only."""
    check_split(model)
    return HeadTerms(_leading(model.disp_head[0], local) if displacement else None,
                     _leading(model.force_head[0], pool(local, mask)))


def pressed_heads(model: CGNN, terms: HeadTerms, cond: torch.Tensor
                  ) -> tuple[torch.Tensor | None, torch.Tensor]:
    """(displacement (B, N, 3) or None, change of force (B,)): C's part of each head's first
    layer added to the surface's terms, then the rest of the head. ``terms`` come from
    :func:`scene_terms`, which checked the model: nothing is checked here, per press."""
    force = _rest(model.force_head, _add_press(model, model.force_head[0], terms.force, cond))
    if terms.disp is None:
        return None, force.squeeze(-1)
    disp = _rest(model.disp_head, _add_press(model, model.disp_head[0], terms.disp, cond))
    return disp, force.squeeze(-1)


def _add_press(model: CGNN, first: nn.Linear, scene: torch.Tensor, cond: torch.Tensor
               ) -> torch.Tensor:
    """``first([features, C])`` from ``scene`` = its features' part: adds C's part."""
    if not model.config.use_condition:
        return scene
    press = cond @ first.weight[:, -CONDITION:].T                        # (B, H)
    return scene + press.view(press.shape[0], *[1] * (scene.dim() - 2), -1)


def _rest(head: nn.Sequential, x: torch.Tensor) -> torch.Tensor:
    """``head`` after its first layer."""
    for layer in islice(head, 1, None):
        x = layer(x)
    return x


def _leading(first: nn.Linear, x: torch.Tensor) -> torch.Tensor:
    """``first`` on the leading ``x.shape[-1]`` inputs of its own (bias in, C's columns left
    out): the head's input ``[x, C]`` is never built, so no (B, N, F + 6) copy is made."""
    return nn.functional.linear(x, first.weight[:, :x.shape[-1]], first.bias)

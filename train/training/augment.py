"""Rigid motions of a batch: rotation augmentation in training, robustness tests in evaluation.

The phantom frame has +z along the surface normal, so a rotation "about the normal" turns x
and y about the vertical line through ``centre``; a tilt turns the scene about the x axis
through ``centre``. Both move the input points, the deformed target points and the tip
positions of the condition together; the change of force, a magnitude, is unchanged. A
90-degree turn of the square phantom about its centre is a press the phantom could have had:
a model that knows the physics, not the coordinates, predicts the same force for it.
"""

from __future__ import annotations

import math

import torch

from train.data import Batch


def about_normal(angles: torch.Tensor) -> torch.Tensor:
    """Rotation matrices (B, 3, 3) turning by ``angles`` (B,) radians about +z."""
    c, s = torch.cos(angles), torch.sin(angles)
    one, zero = torch.ones_like(c), torch.zeros_like(c)
    return torch.stack([c, -s, zero, s, c, zero, zero, zero, one], dim=-1).reshape(-1, 3, 3)


def tilt(angle_deg: float, count: int) -> torch.Tensor:
    """``count`` copies of the rotation by ``angle_deg`` about +x, (count, 3, 3)."""
    a = math.radians(angle_deg)
    c, s = math.cos(a), math.sin(a)
    r = torch.tensor([[1.0, 0.0, 0.0], [0.0, c, -s], [0.0, s, c]])
    return r.expand(count, 3, 3)


def move_batch(b: Batch, rotations: torch.Tensor, centre: torch.Tensor) -> Batch:
    """The batch turned by ``rotations`` (B, 3, 3) about ``centre`` (3,): p -> R (p - c) + c."""
    r = rotations.to(b.points)
    c = centre.to(b.points)

    def turn(p: torch.Tensor) -> torch.Tensor:
        return (p - c) @ r.transpose(1, 2) + c

    tips = turn(b.cond.reshape(-1, 2, 3)).reshape(b.cond.shape)
    return Batch(turn(b.points), turn(b.target), b.mask, tips, b.dforce)

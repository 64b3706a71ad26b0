"""Normalisation of the cGNN's inputs and outputs, fitted on training data, kept in checkpoints.

Points and tips share one transform (they live in one frame, and the network must see where the
tip is relative to the surface): ``(p - centre) / scale`` with one centre (3,) and one scalar
scale. Displacements are divided by ``disp_scale`` and the change of force by ``force_scale``
(their RMS over the training examples), so both heads learn numbers of order one.

With the training conditions (``fit(..., cond=)``) it also keeps the training envelope, what a
:class:`train.Predictor` checks a press against (:class:`Envelope`): the shortest and longest
press, the lowest tip end, the highest tip start above the surface and the range of the change
of force. The shortest press also sets the no-motion gate
(:func:`train.model.si_units.press_gate`). Where it is unknown (``envelope`` None: a checkpoint
of a version that did not keep it) only the distance checks apply.
"""

from __future__ import annotations

from collections.abc import Iterable
from dataclasses import asdict, dataclass
from typing import Any

import numpy as np
import torch

TIP_POINT = 1e-4     # m: a point this near the tip is the tip's own (the lab's tip marker)


@dataclass(frozen=True)
class Envelope:
    """What the training examples span (plain floats: metres, newtons)."""

    press_min: float       # m: the shortest press |tip end - tip start| (of those that move)
    press_max: float       # m: the longest
    tip_lowest: float      # m: the lowest tip end's z
    gap_max: float         # m: the highest tip start above the surface (:func:`tip_height`)
    force_min: float       # N: the range of the change of force
    force_max: float
    top: float | None = None   # m: the highest training point's z (the rest surface is at 0
    #                            in the phantom frame); None: unknown

    @classmethod
    def fit(cls, cond: np.ndarray, dforce: np.ndarray, gap_max: float, top: float
            ) -> Envelope:
        """From every training example's condition (M, 6) and change of force (M,), the
        highest tip start above the surface (:func:`highest_tip`) and the highest point."""
        length = np.linalg.norm(cond[:, 3:] - cond[:, :3], axis=1)
        moved = length[length > 0]
        return cls(press_min=float(moved.min()) if len(moved) else 0.0,
                   press_max=float(length.max()), tip_lowest=float(cond[:, 5].min()),
                   gap_max=gap_max, force_min=float(dforce.min()),
                   force_max=float(dforce.max()), top=top)


def highest_tip(points: np.ndarray, valid: np.ndarray, tips: np.ndarray) -> float:
    """The highest of tips (M, 3) above their surfaces (M, N, 3) with validity (M, N)
    (:func:`tip_height`); 0 when none has a surface."""
    height = [h for t, p, v in zip(tips, points, valid, strict=True)
              if np.isfinite(h := tip_height(t, p[v]))]
    return max(height, default=0.0)


def tip_height(tip: np.ndarray, points: np.ndarray) -> float:
    """How high ``tip`` (3,) lies above the surface ``points`` (N, 3): its z less that of the
    point nearest it in x, y, leaving out a point at the tip itself (the lab's points include
    the tip's marker); NaN when no other point is left."""
    other = points[np.linalg.norm(points - tip, axis=1) > TIP_POINT]
    if len(other) == 0:
        return float("nan")
    return float(tip[2] - other[np.argmin(((other[:, :2] - tip[:2]) ** 2).sum(1)), 2])


def _xyz(values: Iterable[float]) -> tuple[float, float, float]:
    """Three numbers (a point) as plain floats."""
    x, y, z = (float(v) for v in values)
    return x, y, z


def _floats(env: dict[str, Any]) -> dict[str, Any]:
    """An :class:`Envelope`'s fields from its :meth:`Normaliser.to_dict` form: plain floats
    (None where unknown)."""
    return {f: None if env[f] is None else float(env[f]) for f in Envelope.__dataclass_fields__}


@dataclass(frozen=True)
class Normaliser:
    """The statistics (plain floats, so a checkpoint needs no unpickling)."""

    centre: tuple[float, float, float]
    scale: float           # m
    disp_scale: float      # m
    force_scale: float     # N
    extent: float          # m: the largest distance of a training point from the centre
    envelope: Envelope | None = None    # None: unknown (not kept)

    @classmethod
    def fit(cls, points: np.ndarray, valid: np.ndarray, disp: np.ndarray,
            dforce: np.ndarray, cond: np.ndarray | None = None) -> Normaliser:
        """From training inputs (M, N, 3), their validity (M, N), displacements (M, N, 3) and
        changes of force (M,); with their conditions (M, 6), the training envelope too."""
        p = points[valid]
        centre = p.mean(axis=0)
        spread = np.linalg.norm(p - centre, axis=1)
        d = np.linalg.norm(disp[valid & np.isfinite(disp).all(-1)], axis=1)
        return cls(centre=_xyz(centre),
                   scale=float(max(np.sqrt(np.mean(spread**2)), 1e-9)),
                   disp_scale=float(max(np.sqrt(np.mean(d**2)), 1e-9)),
                   force_scale=float(max(np.sqrt(np.mean(np.square(dforce))), 1e-9)),
                   extent=float(spread.max()),
                   envelope=None if cond is None else Envelope.fit(
                       cond, dforce, highest_tip(points, valid, cond[:, :3]),
                       float(p[:, 2].max())))

    def to_dict(self) -> dict:
        """Plain types, for a checkpoint loaded with ``weights_only``."""
        return {k: (list(v) if isinstance(v, tuple) else v) for k, v in asdict(self).items()}

    @classmethod
    def from_dict(cls, d: dict) -> Normaliser:
        """From :meth:`to_dict`'s form."""
        env = d["envelope"]
        return cls(centre=_xyz(d["centre"]), scale=float(d["scale"]),
                   disp_scale=float(d["disp_scale"]), force_scale=float(d["force_scale"]),
                   extent=float(d["extent"]),
                   envelope=None if env is None else Envelope(**_floats(env)))

    def points(self, p: torch.Tensor) -> torch.Tensor:
        """Points (..., 3) in metres -> network units."""
        return (p - p.new_tensor(self.centre)) / self.scale

    def condition(self, c: torch.Tensor) -> torch.Tensor:
        """C = [tip start, tip end] (..., 6) in metres -> network units."""
        return self.points(c.reshape(*c.shape[:-1], 2, 3)).reshape(c.shape)

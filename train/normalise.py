"""Normalisation of the cGNN's inputs and outputs, fitted on training data, kept in checkpoints.

Points and tips share one transform (they live in one frame, and the network must see where the
tip is relative to the surface): ``(p - centre) / scale`` with one centre (3,) and one scalar
scale. Displacements are divided by ``disp_scale`` and the change of force by ``force_scale``
(their RMS over the training examples), so both heads learn numbers of order one.
"""

from __future__ import annotations

from dataclasses import asdict, dataclass

import numpy as np
import torch


@dataclass(frozen=True)
class Normaliser:
    """The statistics (plain floats, so a checkpoint needs no unpickling)."""

    centre: tuple[float, float, float]
    scale: float           # m
    disp_scale: float      # m
    force_scale: float     # N
    extent: float          # m: the largest distance of a training point from the centre

    @classmethod
    def fit(cls, points: np.ndarray, valid: np.ndarray, disp: np.ndarray,
            dforce: np.ndarray) -> Normaliser:
        """From training inputs (M, N, 3), their validity (M, N), displacements (M, N, 3) and
        changes of force (M,)."""
        p = points[valid]
        centre = p.mean(axis=0)
        spread = np.linalg.norm(p - centre, axis=1)
        d = np.linalg.norm(disp[valid & np.isfinite(disp).all(-1)], axis=1)
        return cls(centre=tuple(float(v) for v in centre),
                   scale=float(max(np.sqrt(np.mean(spread**2)), 1e-9)),
                   disp_scale=float(max(np.sqrt(np.mean(d**2)), 1e-9)),
                   force_scale=float(max(np.sqrt(np.mean(np.square(dforce))), 1e-9)),
                   extent=float(spread.max()))

    def to_dict(self) -> dict:
        return {k: (list(v) if isinstance(v, tuple) else v) for k, v in asdict(self).items()}

    @classmethod
    def from_dict(cls, d: dict) -> Normaliser:
        return cls(centre=tuple(float(v) for v in d["centre"]), scale=float(d["scale"]),
                   disp_scale=float(d["disp_scale"]), force_scale=float(d["force_scale"]),
                   extent=float(d["extent"]))

    def points(self, p: torch.Tensor) -> torch.Tensor:
        """Points (..., 3) in metres -> network units."""
        return (p - p.new_tensor(self.centre)) / self.scale

    def condition(self, c: torch.Tensor) -> torch.Tensor:
        """C = [tip start, tip end] (..., 6) in metres -> network units."""
        return self.points(c.reshape(*c.shape[:-1], 2, 3)).reshape(c.shape)

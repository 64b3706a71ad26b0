"""Using a trained cGNN: ``Predictor.load(path).predict(points, condition)``.

Points are (N, 3) float32 in metres in the phantom frame (any N >= k + 1: 26 lab points, 1024
MSM masses, a mesh's vertices); the condition is C = [tip start, tip end] (6,), metres.
``predict`` gives the deformed points and the change of force; ``predict_force`` (a haptic
loop at 1 kHz) runs the graph layers and the force head only.

Refused with ValueError: fewer than k + 1 points, a non-finite value, or coordinates in another
unit (farther from the training data's centre than 20 times its extent: millimetres fed where
metres belong). Flagged, not refused: a condition or points beyond 1.5 times the training extent
set ``extrapolating`` (True after such a call) and warn: the model is outside what it learned.
Duplicate points are allowed (they are each other's nearest neighbours).
"""

from __future__ import annotations

import warnings
from pathlib import Path

import numpy as np
import torch

from train.checkpoint import load_checkpoint, model_from

UNIT_FACTOR = 20.0
EXTRAPOLATION_FACTOR = 1.5


class Predictor:
    """A trained model on one device, ready for single predictions."""

    def __init__(self, model: torch.nn.Module, norm, device: torch.device) -> None:
        self.model, self.norm, self.device = model, norm, device
        self.k = model.config.k
        self.extrapolating = False

    @classmethod
    def load(cls, path: str | Path, device: str = "cpu") -> Predictor:
        """From a checkpoint file or a run folder (its ``best.pt``)."""
        path = Path(path)
        if path.is_dir():
            path = path / "best.pt"
        dev = torch.device(device)
        model, norm = model_from(load_checkpoint(path, dev), dev)
        return cls(model, norm, dev)

    def _inputs(self, points: np.ndarray, condition: np.ndarray
                ) -> tuple[torch.Tensor, torch.Tensor, torch.Tensor]:
        p = np.asarray(points, dtype=np.float32)
        c = np.asarray(condition, dtype=np.float32).reshape(-1)
        if p.ndim != 2 or p.shape[1] != 3:
            raise ValueError(f"points must be (N, 3), got {p.shape}")
        if len(p) < self.k + 1:
            raise ValueError(f"{len(p)} points: the graph needs at least k + 1 = {self.k + 1}")
        if c.shape != (6,):
            raise ValueError(f"condition must be 6 values (tip start, tip end), got {c.shape}")
        if not (np.isfinite(p).all() and np.isfinite(c).all()):
            raise ValueError("points and condition must be finite (no NaN or inf)")
        self._check_range(np.concatenate([p, c.reshape(2, 3)]))
        pt = self.norm.points(torch.from_numpy(p).to(self.device)).unsqueeze(0)
        ct = self.norm.condition(torch.from_numpy(c).to(self.device)).unsqueeze(0)
        return torch.from_numpy(p).to(self.device), pt, ct

    def _check_range(self, xyz: np.ndarray) -> None:
        far = float(np.linalg.norm(xyz - np.asarray(self.norm.centre), axis=1).max())
        extent = max(self.norm.extent, 1e-9)
        if far > UNIT_FACTOR * extent:
            raise ValueError(f"a point lies {far:.3g} from the training data's centre, "
                             f"{far / extent:.0f} times its extent: are these millimetres? "
                             "Points and condition are metres in the phantom frame")
        self.extrapolating = far > EXTRAPOLATION_FACTOR * extent
        if self.extrapolating:
            warnings.warn(f"input reaches {far / extent:.1f} times the training extent: the "
                          "model extrapolates", stacklevel=3)

    @torch.inference_mode()
    def predict(self, points: np.ndarray, condition: np.ndarray) -> tuple[np.ndarray, float]:
        """Deformed points (N, 3) float32 in metres, and the change of force in newtons."""
        raw, p, c = self._inputs(points, condition)
        disp, df = self.model(p, c)
        deformed = raw + disp[0] * self.norm.disp_scale
        return deformed.cpu().numpy(), float(df[0]) * self.norm.force_scale

    @torch.inference_mode()
    def predict_force(self, points: np.ndarray, condition: np.ndarray) -> float:
        """The change of force (N) alone: the displacement head is not run."""
        _, p, c = self._inputs(points, condition)
        return float(self.model.forward_force(p, c)[0]) * self.norm.force_scale

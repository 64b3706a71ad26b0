"""Using a trained cGNN: ``Predictor.load(path).predict(points, condition)``.

Points are (N, 3) float32 in metres in the phantom frame (any N >= k + 1: 26 lab points, 1024
MSM masses, a mesh's vertices); the condition is C = [tip start, tip end] (6,), metres.
``predict`` gives the deformed points and the change of force; ``predict_force`` (a haptic
loop at 1 kHz) skips the displacement head (except on the paper's network's first press of a
scene, which keeps both heads' terms for the presses after it).

What is done once, not per call: the network runs in ONNX Runtime where it is installed (CPU;
``backend="torch"`` keeps torch, the only choice on a GPU), and a scene's points are checked and
their 3-D neighbour graph (the first layer's) built once, then reused while the caller passes
the same points again (a mesh pressed at 1 kHz).

What a press needs depends on the model:
- the paper's network (no tip offsets) reads C only in its heads, so a surface's features are
  the same for every press. A scene's first press runs the whole network once and keeps each
  head's surface terms; every later press on it runs the heads alone (C's part of their first
  layer and the rest): the same answer, at a fraction of the time. ``region=R`` (metres) then
  runs the displacement head on the points within R of the tip's path only and leaves the
  rest at rest; the force is always the whole surface's.
- with tip offsets (our recipe) every layer reads the press, so every press runs the whole
  network. ``region=R`` runs it only on the points within R of the tip's path and the graph's
  rings around them, and leaves the rest where they are; the force head pools over that
  region (:mod:`train.region`).
Either way region mode is how a 4096-point mesh runs at haptic rates; for the paper's network
on a mesh that changes every call it saves nothing (each new mesh runs the whole network, so
that a press's answer never depends on which presses came before). ``DEFAULT_REGION`` is
the radius the benchmarks time; what a radius costs in error is measured by
``benchmarks/region_study.py`` (the speed-accuracy report's region rows), not assumed.

Refused with ValueError: fewer than k + 1 points, a non-finite value, or coordinates in another
unit (farther from the training data's centre than 20 times its extent: millimetres fed where
metres belong). Flagged, not refused: a condition or points beyond 1.5 times the training extent
set ``extrapolating`` (True after such a call) and warn: the model is outside what it learned.
Duplicate points are allowed (they are each other's nearest neighbours).
"""

from __future__ import annotations

import warnings
from dataclasses import dataclass
from pathlib import Path

import numpy as np
import torch

from train.backends import make_backend
from train.checkpoint import load_checkpoint, model_from
from train.region import near_path, neighbour_table, region
from train.si_model import SIModel

UNIT_FACTOR = 20.0
EXTRAPOLATION_FACTOR = 1.5
DEFAULT_REGION = 0.03     # m: the radius benchmarks/bench_cgnn.py times


@dataclass
class Scene:
    """A set of points, checked, with its neighbour graph: kept while the caller reuses it."""

    points: np.ndarray         # (N, 3) float32, a private copy
    neighbours: np.ndarray     # (N, k) int64
    reach: float               # the farthest point's distance from the training centre, m
    terms: tuple[np.ndarray, np.ndarray] | None = None   # a press-independent model's
    #                                                 head terms, once its first press has run


class Predictor:
    """A trained model, ready for single predictions."""

    def __init__(self, si: SIModel, device: torch.device, backend: str = "auto") -> None:
        self.norm, self.k = si.norm, si.model.config.k
        self.hops = len(si.model.convs)
        self.press_independent = si.model.press_independent
        self.backend = make_backend(si, device, backend)
        self.extrapolating = False
        self._scene: Scene | None = None

    @classmethod
    def load(cls, path: str | Path, device: str = "cpu", backend: str = "auto") -> Predictor:
        """From a checkpoint file or a run folder (its ``best.pt``); ``backend`` is ``auto``
        (ONNX Runtime on a CPU where installed), ``onnx`` or ``torch``."""
        path = Path(path)
        if path.is_dir():
            path = path / "best.pt"
        dev = torch.device(device)
        return cls(SIModel(*model_from(load_checkpoint(path, dev), dev)), dev, backend)

    def predict(self, points: np.ndarray, condition: np.ndarray, region: float | None = None
                ) -> tuple[np.ndarray, float]:
        """Deformed points (N, 3) float32 in metres, and the change of force in newtons."""
        scene, c = self._scene_of(points), self._condition(condition)
        if self.press_independent:
            return self._pressed(scene, c, region)
        if region is None:
            deformed, df = self.backend.run("full", scene.points[None], c, scene.neighbours[None])
            return deformed[0], float(df[0])
        core, used = self._region(scene, c, region)
        sub = scene.points[used]
        moved, df = self.backend.run("full", sub[None], c, neighbour_table(sub, self.k)[None])
        deformed = scene.points.copy()
        deformed[core] = moved[0, : len(core)]
        return deformed, float(df[0])

    def predict_force(self, points: np.ndarray, condition: np.ndarray,
                      region: float | None = None) -> float:
        """The change of force (N) alone: the displacement head is not run (but for the
        paper's network's first press of a new scene, which keeps both heads' terms)."""
        scene, c = self._scene_of(points), self._condition(condition)
        if self.press_independent:           # the whole surface's force, from its terms
            self._check_radius(region)
            if scene.terms is None:
                return self._pressed(scene, c, None)[1]
            return float(self.backend.run("pressed_force", scene.terms[1], c)[0][0])
        if region is None:
            return float(self.backend.run("force", scene.points[None], c,
                                          scene.neighbours[None])[0][0])
        sub = scene.points[self._region(scene, c, region)[1]]
        return float(self.backend.run("force", sub[None], c,
                                      neighbour_table(sub, self.k)[None])[0][0])

    def _pressed(self, scene: Scene, c: np.ndarray, radius: float | None
                 ) -> tuple[np.ndarray, float]:
        """A press-independent model: a new scene runs the network once and keeps its head
        terms; a known one runs the heads alone, in a region on the core's points only."""
        self._check_radius(radius)
        core = slice(None) if radius is None else \
            near_path(scene.points, c[0, :3], c[0, 3:], radius, self.k + 1)
        if scene.terms is None:
            *terms, moved, df = self.backend.run("new_scene", scene.points[None],
                                                 scene.neighbours[None], c)
            scene.terms = (terms[0], terms[1])
            moved = moved[:, core]
        else:
            disp_terms, force_terms = scene.terms
            moved, df = self.backend.run("pressed", scene.points[None, core],
                                         disp_terms[:, core], force_terms, c)
        if radius is None:
            return moved[0], float(df[0])
        deformed = scene.points.copy()
        deformed[core] = moved[0]
        return deformed, float(df[0])

    def _region(self, scene: Scene, c: np.ndarray, radius: float
                ) -> tuple[np.ndarray, np.ndarray]:
        self._check_radius(radius)
        return region(scene.points, scene.neighbours, c[0, :3], c[0, 3:], radius, self.hops)

    @staticmethod
    def _check_radius(radius: float | None) -> None:
        if radius is not None and not (np.isfinite(radius) and radius > 0):
            raise ValueError(f"region must be a positive radius in metres, got {radius}")

    def _scene_of(self, points: np.ndarray) -> Scene:
        """The cached scene when ``points`` are the last call's, else a new one, checked."""
        p = np.asarray(points, dtype=np.float32)
        old = self._scene
        if old is not None and old.points.shape == p.shape and np.array_equal(old.points, p):
            return old
        if p.ndim != 2 or p.shape[1] != 3:
            raise ValueError(f"points must be (N, 3), got {p.shape}")
        if len(p) < self.k + 1:
            raise ValueError(f"{len(p)} points: the graph needs at least k + 1 = {self.k + 1}")
        if not np.isfinite(p).all():
            raise ValueError("points and condition must be finite (no NaN or inf)")
        p = p.copy()
        self._scene = Scene(p, neighbour_table(p, self.k), self._reach(p))
        return self._scene

    def _condition(self, condition: np.ndarray) -> np.ndarray:
        """C as (1, 6) float32, checked; sets ``extrapolating`` for this call."""
        c = np.asarray(condition, dtype=np.float32).reshape(-1)
        if c.shape != (6,):
            raise ValueError(f"condition must be 6 values (tip start, tip end), got {c.shape}")
        if not np.isfinite(c).all():
            raise ValueError("points and condition must be finite (no NaN or inf)")
        far = max(self._reach(c.reshape(2, 3)), self._scene.reach)
        self.extrapolating = far > EXTRAPOLATION_FACTOR * self._extent
        if self.extrapolating:
            warnings.warn(f"input reaches {far / self._extent:.1f} times the training extent: "
                          "the model extrapolates", stacklevel=3)
        return c[None]

    @property
    def _extent(self) -> float:
        return max(self.norm.extent, 1e-9)

    def _reach(self, xyz: np.ndarray) -> float:
        """The farthest of ``xyz`` from the training centre; refused if in another unit."""
        far = float(np.sqrt(((xyz - np.asarray(self.norm.centre)) ** 2).sum(1).max()))
        if far > UNIT_FACTOR * self._extent:
            raise ValueError(f"a point lies {far:.3g} from the training data's centre, "
                             f"{far / self._extent:.0f} times its extent: are these millimetres?"
                             " Points and condition are metres in the phantom frame")
        return far

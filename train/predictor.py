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
- the paper's network and the head-offset one (our recipe's) read the press only in their
  heads, so a surface's features are the same for every press. A scene's first press runs
  the whole network once and keeps each head's surface terms; every later press on it runs
  the heads alone (the press's part of their first layer and the rest): the same answer, at
  a fraction of the time. ``region=R`` (metres) then
  runs the displacement head on the points within R of the tip's path only and leaves the
  rest at rest; the force is always the whole surface's.
- with tip offsets every layer reads the press, so every press runs the whole
  network. ``region=R`` runs it only on the points within R of the tip's path and the graph's
  rings around them, and leaves the rest where they are; the force head pools over that
  region (:mod:`train.region`).
Either way region mode is how a 4096-point mesh runs at haptic rates; for a press-independent
network on a mesh that changes every call it saves nothing (each new mesh runs the whole network, so
that a press's answer never depends on which presses came before). ``DEFAULT_REGION`` is
the radius the benchmarks time; what a radius costs in error is measured by
``benchmarks/region_study.py`` (the speed-accuracy report's region rows), not assumed.

A tip that does not move (C = [c, c]) moves nothing and changes no force: the network's outputs
are gated by the press length (:func:`train.si_model.press_gate`), on every backend. The answer
does not depend on the order of the points (ties between neighbours are broken by the points'
coordinates: :func:`train.edgeconv.knn`). Above ``LARGE`` points a call that builds the graph
runs in torch, whose kNN works in pieces (memory linear in N); ONNX Runtime's is one N x N
matrix.

Refused with ValueError: fewer than k + 1 points, a non-finite value, or coordinates farther
from the training data's centre than 20 times its extent (the message says how far, in metres,
and asks "millimetres?" only when the input divided by 1000 would fit the training data).
Flagged, not refused: ``extrapolating`` is True after a call outside the training envelope, with
a warning saying where: points or condition beyond 1.5 times the training extent, and, for a
checkpoint that keeps its envelope (:class:`train.normalise.Envelope`), a press longer than the
longest learned or shorter than the shortest (below a tenth of it the gate scales the answer
down linearly; a press of length 0 is exact, not flagged), a tip end below the lowest training
tip end, points higher than any learned (a frame off the rest surface), a tip start higher
above the surface than any learned
(:func:`train.normalise.tip_height`), or a change of force beyond the training range (each
with a margin of ``MARGIN`` of the longest press, or of the force range).
Duplicate points are allowed (they are each other's nearest neighbours).
"""

from __future__ import annotations

import warnings
from collections.abc import Callable
from dataclasses import dataclass
from functools import cached_property
from pathlib import Path

import numpy as np
import torch
from scipy.spatial import cKDTree

from train.backends import TorchBackend, make_backend
from train.checkpoint import load_checkpoint, model_from
from train.head_split import check_split
from train.normalise import tip_height
from train.region import near_path, neighbour_table, region
from train.si_model import SIModel, press_entries

UNIT_FACTOR = 20.0
EXTRAPOLATION_FACTOR = 1.5
MARGIN = 0.1              # of the training press (or force) range, beyond its envelope
DEFAULT_REGION = 0.03     # m: the radius benchmarks/bench_cgnn.py times
LARGE = 8192              # points: above it a call that builds the graph runs in torch
GRAPH_ENTRIES = ("full", "force", "new_scene")      # the entries that search neighbours
NEAREST = 8               # points nearest the tip in x, y that its height is measured from


@dataclass
class Scene:
    """A set of points, checked, with its neighbour graph: kept while the caller reuses it."""

    points: np.ndarray         # (N, 3) float32, a private copy
    neighbours: np.ndarray     # (N, k) int64
    reach: float               # the farthest point's distance from the training centre, m
    terms: tuple[np.ndarray, np.ndarray] | None = None   # a press-independent model's
    #                                                 head terms, once its first press has run
    plan: cKDTree | None = None   # of the points' x, y, once a tip's height is asked
    last: tuple[bytes, float] = (b"", 0.0)    # the last tip asked about, and its height

    @cached_property
    def top(self) -> float:
        """The highest point's z, m."""
        return float(self.points[:, 2].max())

    def height(self, tip: np.ndarray) -> float:
        """The tip's height above the surface (:func:`train.normalise.tip_height`), from the
        points nearest it in x, y (a tree: a 1 kHz loop does not scan a mesh per call; a
        press's start, the same call after call, is looked up once)."""
        if tip.tobytes() == self.last[0]:
            return self.last[1]
        if self.plan is None:
            self.plan = cKDTree(self.points[:, :2])
        _, idx = self.plan.query(tip[:2], k=min(NEAREST, len(self.points)))
        h = tip_height(tip, self.points[np.atleast_1d(idx)])
        h = tip_height(tip, self.points) if np.isnan(h) else h
        self.last = (tip.tobytes(), h)
        return h


class Predictor:
    """A trained model, ready for single predictions."""

    def __init__(self, si: SIModel, device: torch.device, backend: str = "auto") -> None:
        self.norm, self.k = si.norm, si.model.config.k
        self.hops = len(si.model.convs)
        self.press_independent = si.model.press_independent
        if self.press_independent:      # a known scene runs its cached head terms
            check_split(si.model)
            self._press_region, self._press_force = press_entries(si)
            self._offsets = si.model.offsets is not None   # the force reads every point
        self.backend = make_backend(si, device, backend)
        self.large = self.backend if self.backend.name == "torch" else TorchBackend(si, device)
        self.extrapolating = False
        self._scene: Scene | None = None
        self._outside: list[str] = []      # this call's reasons to flag it
        self._still = False                # this call's tip does not move
        self.point_names: list[str] | None = None   # the points it was trained on (load)

    @classmethod
    def load(cls, path: str | Path, device: str = "cpu", backend: str = "auto") -> Predictor:
        """From a checkpoint file or a run folder (its ``best.pt``); ``backend`` is ``auto``
        (ONNX Runtime on a CPU where installed), ``onnx`` or ``torch``."""
        path = Path(path)
        if path.is_dir():
            path = path / "best.pt"
        dev = torch.device(device)
        state = load_checkpoint(path, dev)
        out = cls(SIModel(*model_from(state, dev)), dev, backend)
        out.point_names = state["meta"]["data"].get("point_names")
        return out

    def predict(self, points: np.ndarray, condition: np.ndarray, region: float | None = None
                ) -> tuple[np.ndarray, float]:
        """Deformed points (N, 3) float32 in metres, and the change of force in newtons."""
        scene, c = self._scene_of(points), self._condition(condition)
        if self.press_independent:
            deformed, df = self._pressed(scene, c, region)
        elif region is None:
            deformed, df = self._run("full", scene.points[None], c, scene.neighbours[None])
            deformed, df = deformed[0], float(df[0])
        else:
            core, used = self._region(scene, c, region)
            sub = scene.points[used]
            moved, df = self._run("full", sub[None], c, neighbour_table(sub, self.k)[None])
            deformed, df = scene.points.copy(), float(df[0])
            deformed[core] = moved[0, : len(core)]
        return deformed, self._flag(df)

    def predict_force(self, points: np.ndarray, condition: np.ndarray,
                      region: float | None = None) -> float:
        """The change of force (N) alone: the displacement head is not run (but for the
        paper's network's first press of a new scene, which keeps both heads' terms)."""
        scene, c = self._scene_of(points), self._condition(condition)
        if self.press_independent:           # the whole surface's force, from its terms
            self._check_radius(region)
            if scene.terms is None:
                return self._flag(self._pressed(scene, c, None)[1])
            return self._flag(float(self._run(self._press_force, scene.terms[1], c,
                                              *self._surface(scene))[0][0]))
        if region is None:
            return self._flag(float(self._run("force", scene.points[None], c,
                                              scene.neighbours[None])[0][0]))
        sub = scene.points[self._region(scene, c, region)[1]]
        return self._flag(float(self._run("force", sub[None], c,
                                          neighbour_table(sub, self.k)[None])[0][0]))

    def _run(self, entry: str, *arrays: np.ndarray) -> list[np.ndarray]:
        """``entry`` on the backend, or in torch where it builds the graph of more than
        ``LARGE`` points (memory linear in N: ONNX Runtime's kNN is one N x N matrix)."""
        big = entry in GRAPH_ENTRIES and arrays[0].shape[1] > LARGE
        return (self.large if big else self.backend).run(entry, *arrays)

    def _pressed(self, scene: Scene, c: np.ndarray, radius: float | None
                 ) -> tuple[np.ndarray, float]:
        """A press-independent model: a new scene runs the network once and keeps its head
        terms; a known one runs the heads alone, in a region on the core's points only."""
        self._check_radius(radius)
        core = slice(None) if radius is None else \
            near_path(scene.points, c[0, :3], c[0, 3:], radius, self.k + 1)
        if scene.terms is None:
            *terms, moved, df = self._run("new_scene", scene.points[None],
                                          scene.neighbours[None], c)
            scene.terms = (terms[0], terms[1])
            moved = moved[:, core]
        else:
            disp_terms, force_terms = scene.terms
            if radius is None:
                moved, df = self._run("pressed", scene.points[None], disp_terms, force_terms, c)
            else:
                moved, df = self._run(self._press_region, scene.points[None, core],
                                      disp_terms[:, core], force_terms, c,
                                      *self._surface(scene))
        if radius is None:
            return moved[0], float(df[0])
        deformed = scene.points.copy()
        deformed[core] = moved[0]
        return deformed, float(df[0])

    def _surface(self, scene: Scene) -> tuple[np.ndarray, ...]:
        """The scene's points, where a press on it reads them (head offsets); else nothing."""
        return (scene.points[None],) if self._offsets else ()

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
        reach = self._reach(p, "a point", lambda: _mm_sized(p, self._extent))
        self._scene = Scene(p, neighbour_table(p, self.k), reach)
        return self._scene

    def _condition(self, condition: np.ndarray) -> np.ndarray:
        """C as (1, 6) float32, checked; gathers this call's reasons to flag it."""
        c = np.asarray(condition, dtype=np.float32).reshape(-1)
        if c.shape != (6,):
            raise ValueError(f"condition must be 6 values (tip start, tip end), got {c.shape}")
        if not np.isfinite(c).all():
            raise ValueError("points and condition must be finite (no NaN or inf)")
        tips = c.reshape(2, 3).astype(np.float64)
        far = max(self._reach(tips, "the tip", lambda: self._mm_tip(tips)), self._scene.reach)
        self._outside = []
        self._still = bool(np.array_equal(tips[0], tips[1]))
        if self._still:                        # no motion: the answer is exact (no change)
            return c[None]
        if far > EXTRAPOLATION_FACTOR * self._extent:
            self._outside.append(f"input reaches {far / self._extent:.1f} times the training "
                                 "extent")
        if self.norm.envelope is not None:
            self._outside += self._beyond(tips, self._scene)
        return c[None]

    def _beyond(self, tips: np.ndarray, scene: Scene) -> list[str]:
        """Where a press lies outside the training envelope (press length, depth, the tip
        start's distance from the surface), in words."""
        env, out = self.norm.envelope, []
        length = float(np.linalg.norm(tips[1] - tips[0]))
        slack = MARGIN * env.press_max
        if length > env.press_max + slack:
            out.append(f"a press of {length * 1e3:.3g} mm, longer than the longest learned "
                       f"({env.press_max * 1e3:.3g} mm)")
        elif 0 < length < env.press_min * (1 - MARGIN):
            out.append(f"a press of {length * 1e3:.3g} mm, shorter than the shortest learned "
                       f"({env.press_min * 1e3:.3g} mm)")
        if tips[1, 2] < env.tip_lowest - slack:
            out.append(f"the tip end {(env.tip_lowest - tips[1, 2]) * 1e3:.3g} mm below the "
                       "lowest learned")
        if env.top is not None and scene.top > env.top + slack:
            out.append(f"points up to {(scene.top - env.top) * 1e3:.3g} mm above the highest "
                       "learned (the rest surface is at z = 0 in the phantom frame)")
        gap = scene.height(tips[0])
        if gap > env.gap_max + slack:
            out.append(f"the tip start {gap * 1e3:.3g} mm above the surface (at most "
                       f"{env.gap_max * 1e3:.3g} mm learned)")
        return out

    def _flag(self, df: float) -> float:
        """Sets ``extrapolating`` for this call and warns, saying where, if the press or its
        predicted change of force lies outside what the model learned; returns ``df``."""
        env = self.norm.envelope
        if env is not None and not self._still:
            slack = MARGIN * max(env.force_max - env.force_min, 1e-9)
            if not env.force_min - slack <= df <= env.force_max + slack:
                self._outside.append(f"a change of force of {df:.3g} N, outside the "
                                     f"{env.force_min:.3g} to {env.force_max:.3g} N learned")
        self.extrapolating = bool(self._outside)
        if self.extrapolating:
            warnings.warn("the model extrapolates: " + "; ".join(self._outside), stacklevel=3)
        return df

    @property
    def _extent(self) -> float:
        return max(self.norm.extent, 1e-9)

    def _mm_tip(self, tips: np.ndarray) -> bool:
        """Whether a tip given in millimetres would fit: divided by 1000 it lies within the
        training extent of the centre and (where the envelope is kept) near the surface."""
        mm = tips / 1000.0
        if np.linalg.norm(mm - np.asarray(self.norm.centre), axis=1).max() > \
                EXTRAPOLATION_FACTOR * self._extent:
            return False
        env = self.norm.envelope
        return env is None or self._scene is None or \
            abs(self._scene.height(mm[0])) <= env.gap_max + MARGIN * env.press_max

    def _reach(self, xyz: np.ndarray, what: str, millimetres: Callable[[], bool]) -> float:
        """The farthest of ``xyz`` from the training centre (m); refused when more than
        ``UNIT_FACTOR`` times the training extent, saying how far (and asking about
        millimetres only when ``millimetres()``: the input / 1000 would fit)."""
        far = float(np.sqrt(((xyz - np.asarray(self.norm.centre)) ** 2).sum(1).max()))
        if far > UNIT_FACTOR * self._extent:
            hint = ": are these millimetres? Points and condition are metres in the phantom " \
                "frame" if millimetres() else ": far outside what it learned (points and " \
                "condition are metres in the phantom frame)"
            raise ValueError(f"{what} lies {far:.3g} m from the training data's centre, "
                             f"{far / self._extent:.0f} times the training extent "
                             f"({self._extent:.3g} m){hint}")
        return far


def _mm_sized(points: np.ndarray, extent: float) -> bool:
    """Whether ``points`` are the size of the training data times 1000 (millimetres): their
    spread about their mean, divided by 1000, is within 20 times the training extent of it."""
    spread = float(np.linalg.norm(points - points.mean(0), axis=1).max()) / 1000.0
    return extent / UNIT_FACTOR <= spread <= UNIT_FACTOR * extent

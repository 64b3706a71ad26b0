"""Using a trained cGNN: ``Predictor.load(path).predict(points, condition)``.

Points (N, 3) and the condition C = [tip start, tip end] (6,) are metres in the phantom frame;
``predict`` gives the deformed points and the change of force (a :class:`Prediction`, with how
far they may be off at a level asked), ``predict_force`` (a haptic loop) the force alone. A
scene's points are checked and their neighbour graph built once, and reused while the caller
passes the same points again. How each network runs a press (a known scene's
head terms, region mode), what is refused (ValueError) and what is flagged (``extrapolating``,
with a warning saying where): docs/model.md, "Using a trained model" and "Latency".
"""

from __future__ import annotations

import math
import warnings
from collections.abc import Callable
from dataclasses import dataclass
from functools import cached_property
from pathlib import Path

import numpy as np
import torch

from train.inference.backends import TorchBackend, make_backend
from train.inference.head_split import check_split
from train.inference.prediction import Prediction
from train.inference.region import near_path, neighbour_table, region
from train.inference.si_model import SIModel, press_entries
from train.intervals.levels import level_index
from train.intervals.lookup import SceneLookup, TableLookup
from train.intervals.table import IntervalTable
from train.model.normalise import tip_height
from train.training.checkpoint import load_checkpoint, model_from

UNIT_FACTOR = 20.0
EXTRAPOLATION_FACTOR = 1.5
MARGIN = 0.1              # of the training press (or force) range, beyond its envelope
DEFAULT_REGION = 0.03     # m: the radius benchmarks/bench_cgnn.py times
LARGE = 8192              # points: above it a call that builds the graph runs in torch
NOT_HOLDING = "; its intervals do not hold there (calibrated inside the envelope)"
GRAPH_ENTRIES = ("full", "force", "new_scene")      # the entries that search neighbours


@dataclass
class Scene:
    """A set of points, checked, with its neighbour graph: kept while the caller reuses it."""

    points: np.ndarray         # (N, 3) float32, a private copy
    neighbours: np.ndarray     # (N, k) int64
    reach: float               # the farthest point's distance from the training centre, m
    terms: tuple[np.ndarray, np.ndarray] | None = None   # a press-independent model's
    #                                                 head terms, once its first press has run
    last: tuple[bytes, float] = (b"", 0.0)    # the last tip asked about, and its height

    @cached_property
    def lookup(self) -> SceneLookup:
        """The points as the interval lookup keeps them, once an interval is asked."""
        return SceneLookup(self.points)

    @cached_property
    def top(self) -> float:
        """The highest point's z, m."""
        return float(self.points[:, 2].max())

    @cached_property
    def bottom(self) -> float:
        """The lowest point's z, m: no tip is higher above the surface than above it."""
        return float(self.points[:, 2].min())

    def height(self, tip: np.ndarray) -> float:
        """The tip's height above the surface (:func:`train.model.normalise.tip_height`, the
        training envelope's measure; NaN where no other point is left), kept for the last tip
        asked (a press's start, the same call after call)."""
        if tip.tobytes() != self.last[0]:
            self.last = (tip.tobytes(), tip_height(tip, self.points))
        return self.last[1]


@dataclass
class CheckedPress:
    """One call's press, checked: its scene, C (1, 6) float32, the radius of region mode
    (None: the whole scene), whether the tip stands still, and the reasons to flag the call
    found before the network runs."""

    scene: Scene
    c: np.ndarray
    radius: float | None
    still: bool
    outside: list[str]
    tips: list[float]          # C as plain floats (what the checks and lookups read)


Answer = tuple[np.ndarray | None, float]    # deformed points (None: force only), change of force


class Predictor:
    """A trained model, ready for single predictions."""

    def __init__(self, si: SIModel, device: torch.device, backend: str = "auto") -> None:
        self.norm, self.k = si.norm, si.model.config.k
        self.hops = len(si.model.convs)
        self.offsets = si.model.offsets
        if self.offsets.press_independent:      # a known scene runs its cached head terms
            check_split(si.model)
            self._press_part, self._press_force = press_entries(si)
        self.backend = make_backend(si, device, backend)
        self.large = self.backend if self.backend.name == "torch" else TorchBackend(si, device)
        self.extrapolating = False
        self._table: TableLookup | None = None      # the checkpoint's intervals, as looked up
        self._scene: Scene | None = None
        self.point_names: list[str] | None = None   # the points it was trained on (load)
        # how a press runs, by whether a region is asked: the heads alone on a known scene
        # (a press-independent network), else the whole network on the scene or the region
        self._ways: dict[bool, Callable[[CheckedPress, bool], Answer]] = \
            {False: self._known, True: self._known} if self.offsets.press_independent \
            else {False: self._whole, True: self._in_region}

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
        if "intervals" in state:
            out.intervals = IntervalTable.from_dict(state["intervals"])
        return out

    @property
    def press_independent(self) -> bool:
        """Whether a known scene's presses run the heads alone."""
        return self.offsets.press_independent

    @property
    def intervals(self) -> IntervalTable | None:
        """The calibrated intervals' table (the checkpoint's, at load); None: absent."""
        return None if self._table is None else self._table.table

    @intervals.setter
    def intervals(self, table: IntervalTable | None) -> None:
        self._table = None if table is None else TableLookup(table)

    def predict(self, points: np.ndarray, condition: np.ndarray, region: float | None = None,
                level: float | None = None) -> Prediction:
        """The deformed points (N, 3) float32 in metres and the change of force in newtons
        (``.points``, ``.dforce``); with ``level`` in (0, 1) also how far they may be off
        (``.sure``, an :class:`~train.intervals.lookup.Interval`: each point's radius, the
        force's interval, calibrated at that level; a table lookup)."""
        index = self._level_index(level)
        press = self._press(points, condition, region)
        deformed, df = self._ways[region is not None](press, False)
        if deformed is None:                 # asked with force_only False: never
            raise RuntimeError("the network gave no deformed points")
        df = self._flag(press, df, NOT_HOLDING if level is not None else "")
        if index is None or level is None or self._table is None:   # all three or none
            return Prediction(deformed, df)
        return Prediction(deformed, df, press.scene.lookup.interval(
            self._table, level, index, press.tips, df, not self.extrapolating))

    def predict_force(self, points: np.ndarray, condition: np.ndarray,
                      region: float | None = None, level: float | None = None
                      ) -> float | tuple[float, tuple[float, float]]:
        """The change of force (N) alone: the displacement head is not run (but for the
        paper's network's first press of a new scene, which keeps both heads' terms); with
        ``level``, also its interval (low, high) N at that level."""
        index = self._level_index(level)
        press = self._press(points, condition, region)
        df = self._flag(press, self._ways[region is not None](press, True)[1],
                        NOT_HOLDING if level is not None else "")
        if index is None or self._table is None:     # both or neither
            return df
        return df, press.scene.lookup.force_interval(self._table, index, press.tips, df)

    def _level_index(self, level: float | None) -> int | None:
        """The index of ``level`` among the table's levels (None without one); refused
        (ValueError, one line) outside (0, 1), or wherever the checkpoint keeps no
        intervals."""
        if level is None:
            return None
        index = level_index(level)
        if self._table is None:
            raise ValueError("intervals absent: this checkpoint keeps none (trained before "
                             "they existed, or without validation presses); retrain it, or "
                             "predict without level")
        return index

    def _known(self, press: CheckedPress, force_only: bool) -> Answer:
        """A press-independent network: a new scene runs the network once and keeps its head
        terms; a known one runs the heads alone (in a region on the core's points only; the
        force is the whole surface's)."""
        scene, c = press.scene, press.c
        core = None if press.radius is None or force_only else \
            near_path(scene.points, c[0, :3], c[0, 3:], press.radius, self.k + 1)
        if scene.terms is None:
            *terms, moved, df = self._run("new_scene", scene.points[None],
                                          scene.neighbours[None], c)
            scene.terms = (terms[0], terms[1])
            return _placed(scene, core, moved[0] if core is None else moved[0, core]), \
                float(df[0])
        disp_terms, force_terms = scene.terms
        if force_only:
            return None, float(self._run(self._press_force, force_terms, c,
                                         *self._surface(scene))[0][0])
        if core is None:
            moved, df = self._run("pressed", scene.points[None], disp_terms, force_terms, c)
        else:
            moved, df = self._run(self._press_part, scene.points[None, core],
                                  disp_terms[:, core], force_terms, c, *self._surface(scene))
        return _placed(scene, core, moved[0]), float(df[0])

    def _whole(self, press: CheckedPress, force_only: bool) -> Answer:
        """The whole network on the whole scene (its graph known)."""
        scene = press.scene
        return self._network(scene.points, scene.neighbours, press.c, force_only)

    def _in_region(self, press: CheckedPress, force_only: bool) -> Answer:
        """The whole network on the points near the tip's path and the rings of neighbours
        its layers read; the rest stay where they are."""
        scene = press.scene
        if press.radius is None:
            raise ValueError("a press in a region needs its radius")
        core, used = region(scene.points, scene.neighbours, press.c[0, :3], press.c[0, 3:],
                            press.radius, self.hops)
        sub = scene.points[used]
        moved, df = self._network(sub, neighbour_table(sub, self.k), press.c, force_only)
        if moved is None:
            return None, df
        deformed = scene.points.copy()
        deformed[core] = moved[: len(core)]
        return deformed, df

    def _network(self, points: np.ndarray, neighbours: np.ndarray, c: np.ndarray,
                 force_only: bool) -> Answer:
        """The whole network (or its force alone) on ``points`` with their graph."""
        if force_only:
            return None, float(self._run("force", points[None], c, neighbours[None])[0][0])
        moved, df = self._run("full", points[None], c, neighbours[None])
        return moved[0], float(df[0])

    def _run(self, entry: str, *arrays: np.ndarray) -> list[np.ndarray]:
        """``entry`` on the backend, or in torch where it builds the graph of more than
        ``LARGE`` points (memory linear in N: ONNX Runtime's kNN is one N x N matrix)."""
        big = entry in GRAPH_ENTRIES and arrays[0].shape[1] > LARGE
        return (self.large if big else self.backend).run(entry, *arrays)

    def _surface(self, scene: Scene) -> tuple[np.ndarray, ...]:
        """The scene's points, where a press on it reads them (offsets in the heads)."""
        return (scene.points[None],) if self.offsets.in_heads else ()

    @staticmethod
    def _check_radius(radius: float | None) -> None:
        if radius is not None and not (np.isfinite(radius) and radius > 0):
            raise ValueError(f"region must be a positive radius in metres, got {radius}")

    def _scene_of(self, points: np.ndarray) -> Scene:
        """The cached scene when ``points`` are the last call's, else a new one, checked."""
        p = np.asarray(points, dtype=np.float32)
        old = self._scene
        if old is not None and old.points.shape == p.shape and bool((old.points == p).all()):
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

    def _press(self, points: np.ndarray, condition: np.ndarray, radius: float | None
               ) -> CheckedPress:
        """This call's press, checked (ValueError: what is refused), with the reasons to
        flag it that the input alone shows. The press's checks run on its six numbers as
        plain floats (a haptic loop calls with a new press every time: numpy's per-call
        cost on a few numbers was most of a known scene's call)."""
        self._check_radius(radius)
        scene = self._scene_of(points)
        c = np.asarray(condition, dtype=np.float32).reshape(-1)
        if c.shape != (6,):
            raise ValueError(f"condition must be 6 values (tip start, tip end), got {c.shape}")
        v = c.tolist()
        if not all(map(math.isfinite, v)):
            raise ValueError("points and condition must be finite (no NaN or inf)")
        start, end = v[:3], v[3:]
        far = max(self._tip_reach(c, start, end, scene), scene.reach)
        still = start == end
        outside: list[str] = []
        if not still:                        # no motion: the answer is exact (no change)
            if far > EXTRAPOLATION_FACTOR * self._extent:
                outside.append(f"input reaches {far / self._extent:.1f} times the training "
                               "extent")
            outside += self._beyond(start, end, scene)
        return CheckedPress(scene, c[None], radius, still, outside, v)

    def _tip_reach(self, c: np.ndarray, start: list[float], end: list[float], scene: Scene
                   ) -> float:
        """The farther tip's distance from the training centre (m); refused as
        :meth:`_reach` refuses (it says how far, and asks about millimetres)."""
        far = max(math.dist(start, self._centre), math.dist(end, self._centre))
        if far > UNIT_FACTOR * self._extent:
            tips = c.reshape(2, 3).astype(np.float64)
            return self._reach(tips, "the tip", lambda: self._mm_tip(tips, scene))
        return far

    def _beyond(self, start: list[float], end: list[float], scene: Scene) -> list[str]:
        """Where a press (its tip start and end, m) lies outside the training envelope
        (press length, depth, the tip start's distance from the surface), in words; nothing
        where the checkpoint keeps no envelope."""
        env = self.norm.envelope
        out: list[str] = []
        if env is None:
            return out
        length = math.dist(start, end)
        slack = MARGIN * env.press_max
        if length > env.press_max + slack:
            out.append(f"a press of {length * 1e3:.3g} mm, longer than the longest learned "
                       f"({env.press_max * 1e3:.3g} mm)")
        elif 0 < length < env.press_min * (1 - MARGIN):
            out.append(f"a press of {length * 1e3:.3g} mm, shorter than the shortest learned "
                       f"({env.press_min * 1e3:.3g} mm)")
        if end[2] < env.tip_lowest - slack:
            out.append(f"the tip end {(env.tip_lowest - end[2]) * 1e3:.3g} mm below the "
                       "lowest learned")
        if env.top is not None and scene.top > env.top + slack:
            out.append(f"points up to {(scene.top - env.top) * 1e3:.3g} mm above the highest "
                       "learned (the rest surface is at z = 0 in the phantom frame)")
        limit = env.gap_max + slack
        if start[2] - scene.bottom > limit and (gap := scene.height(np.array(start))) > limit:
            out.append(f"the tip start {gap * 1e3:.3g} mm above the surface (at most "
                       f"{env.gap_max * 1e3:.3g} mm learned)")       # (no lower point: no search)
        return out

    def _flag(self, press: CheckedPress, df: float, note: str = "") -> float:
        """Sets ``extrapolating`` for this call and warns, saying where, if the press or its
        predicted change of force lies outside what the model learned; returns ``df``."""
        outside, env = list(press.outside), self.norm.envelope
        if env is not None and not press.still:
            slack = MARGIN * max(env.force_max - env.force_min, 1e-9)
            if not env.force_min - slack <= df <= env.force_max + slack:
                outside.append(f"a change of force of {df:.3g} N, outside the "
                               f"{env.force_min:.3g} to {env.force_max:.3g} N learned")
        self.extrapolating = bool(outside)
        if self.extrapolating:
            warnings.warn("the model extrapolates: " + "; ".join(outside) + note, stacklevel=3)
        return df

    @property
    def _extent(self) -> float:
        return max(self.norm.extent, 1e-9)

    @cached_property
    def _centre(self) -> tuple[float, float, float]:
        """The training data's centre (m), as plain floats."""
        x, y, z = (float(v) for v in self.norm.centre)
        return x, y, z

    def _mm_tip(self, tips: np.ndarray, scene: Scene) -> bool:
        """Whether a tip given in millimetres would fit: divided by 1000 it lies within the
        training extent of the centre and (where the envelope is kept) near the surface."""
        mm = tips / 1000.0
        if np.linalg.norm(mm - np.asarray(self.norm.centre), axis=1).max() > \
                EXTRAPOLATION_FACTOR * self._extent:
            return False
        env = self.norm.envelope
        return env is None or abs(scene.height(mm[0])) <= env.gap_max + MARGIN * env.press_max

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


def _placed(scene: Scene, core: np.ndarray | None, moved: np.ndarray) -> np.ndarray:
    """The deformed scene: ``moved`` is all of it (``core`` None), or its core's points, the
    rest staying where they are."""
    if core is None:
        return moved
    deformed = scene.points.copy()
    deformed[core] = moved
    return deformed

"""The interval table: per bin and level, a point's radius and the force's half-width, in the
plain form a checkpoint keeps (``best.pt``'s ``intervals``, read with ``weights_only``) and an
ONNX file's metadata carry (JSON).

A point's score is its displacement error norm, so its interval is a sphere of a radius
about its predicted position; the force's is |dF error|, an interval dF +- half-width. The
points' radii are binned by :data:`~train.intervals.features.POINT_FEATURES`, the force's
half-widths by :data:`~train.intervals.features.FORCE_FEATURES`, at every level of
:data:`~train.intervals.levels.LEVELS`; how they are fitted is :mod:`train.intervals.quantiles`.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from train.intervals.features import FORCE_FEATURES, POINT_FEATURES
from train.intervals.levels import LEVELS
from train.intervals.quantiles import LEADS, MIN_COUNT, SPLITS, binned_quantiles


@dataclass(frozen=True)
class Bins:
    """Binned quantiles of one score: per feature its edges (bin i holds values in
    [edge i-1, edge i)), and per bin and level the width (radius or half-width, inf where the
    calibration cannot bound it) and how many calibration scores it stands on."""

    edges: tuple[tuple[float, ...], ...]
    width: np.ndarray          # (*shape, Q) float64
    count: np.ndarray          # (*shape, Q) int64

    @classmethod
    def fit(cls, scores: np.ndarray, features: np.ndarray, splits: tuple[tuple[float, ...], ...],
            lead: tuple[float | None, ...] | None = None) -> Bins:
        """From scores (M,) and their features (M, K)
        (:func:`~train.intervals.quantiles.binned_quantiles`)."""
        return cls(*binned_quantiles(scores, features, splits, lead))

    def widths(self, level: int, *features: np.ndarray | float) -> np.ndarray:
        """The width at level index ``level`` for each value of ``features`` (one array or
        scalar per feature, broadcast together)."""
        flat = self.width[..., level].ravel()
        i: int | np.ndarray = 0
        for e, f in zip(self.edges, features, strict=True):
            i = i * (len(e) + 1) + np.searchsorted(e, f, side="right")
        return flat[i]

    def to_dict(self) -> dict:
        """Plain types (an unbounded width as None)."""
        return {"edges": [list(e) for e in self.edges],
                # numpy 2's stubs refuse None as a choice of where (an object array here)
                "width": np.where(np.isfinite(self.width), self.width, None).tolist(),  # type: ignore[call-overload, unused-ignore]
                "count": self.count.tolist()}

    @classmethod
    def from_dict(cls, d: dict) -> Bins:
        """From :meth:`to_dict`'s form; ValueError where the shapes do not agree."""
        edges = tuple(tuple(float(v) for v in e) for e in d["edges"])
        shape = (*(len(e) + 1 for e in edges), len(LEVELS))
        width = np.array(d["width"], dtype=np.float64)
        count = np.array(d["count"], dtype=np.int64)
        if width.shape != shape or count.shape != shape:
            raise ValueError(f"interval bins of shape {width.shape}, their edges need {shape}")
        if (width < 0).any() or (count < 1).any():
            raise ValueError("interval widths must be non-negative, each on some scores")
        return cls(edges, np.where(np.isnan(width), np.inf, width), count)


@dataclass(frozen=True)
class IntervalTable:
    """The intervals a checkpoint keeps: the points' radii, the force's half-widths, and how
    many presses and examples they were calibrated on."""

    points: Bins
    force: Bins
    presses: int
    examples: int

    @classmethod
    def fit(cls, point_scores: np.ndarray, point_features: np.ndarray,
            force_scores: np.ndarray, force_features: np.ndarray, presses: int
            ) -> IntervalTable:
        """From the calibration's point scores (M,) m with their features (M, 3) and force
        scores (E,) N with theirs (E, 2) (:class:`~train.intervals.features.PressFeatures`),
        of ``presses`` held-out presses."""
        return cls(Bins.fit(point_scores, point_features,
                            tuple(SPLITS[f] for f in POINT_FEATURES),
                            tuple(LEADS.get(f) for f in POINT_FEATURES)),
                   Bins.fit(force_scores, force_features,
                            tuple(SPLITS[f] for f in FORCE_FEATURES)),
                   presses, len(force_scores))

    def radii(self, level: int, distance: np.ndarray, depth: np.ndarray | float,
              height: np.ndarray | float) -> np.ndarray:
        """Each point's radius m at level index ``level``, from its distance from the tip's
        path and its press's depth and tip height (arrays broadcast together)."""
        return self.points.widths(level, distance, depth, height)

    def to_dict(self) -> dict:
        """Plain types, for a checkpoint loaded with ``weights_only`` and for JSON."""
        return {"levels": list(LEVELS), "point_features": list(POINT_FEATURES),
                "force_features": list(FORCE_FEATURES), "min_count": MIN_COUNT,
                "points": self.points.to_dict(), "force": self.force.to_dict(),
                "presses": self.presses, "examples": self.examples}

    @classmethod
    def from_dict(cls, d: dict) -> IntervalTable:
        """From :meth:`to_dict`'s form; ValueError where it is not one."""
        if list(d["levels"]) != list(LEVELS):
            raise ValueError("interval levels are not 0.01 .. 0.99")
        return cls(Bins.from_dict(d["points"]), Bins.from_dict(d["force"]),
                   int(d["presses"]), int(d["examples"]))

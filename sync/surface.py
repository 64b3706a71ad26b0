"""The tip against the phantom's rest surface: its depth below it, and where each press touched
it. A flat phantom's surface is its rest plane (:mod:`calib.rest_plane`); a curved one's is its
shape, registered to the markers (:mod:`calib.shape_registration`), and there a press's depth
runs along the surface's normal at the point its tip touched."""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from calib.rest_plane import mean_seen, rest_surface
from calib.shape_registration import Registration, register_markers
from core.errors import BadInput
from data_schema.phantom import PhantomLayout
from data_schema.shape import Shape
from sync.presses import Press, PressRecord

TOUCH_OFF_M = 3e-3      # a curved press's tip this far outside the shape at onset never touched
EXACT_DEPTH_M = 5e-3    # the depth series is exact this near the surface (the touches, the
                        # crossings); beyond, the shape's first guess (data_schema/shape.py)


@dataclass(frozen=True)
class Curved:
    """A curved phantom's shape, and its registration to the markers."""

    registration: Registration
    shape: Shape


@dataclass(frozen=True)
class RestSurface:
    """What depth is measured from: the rest plane (``point``, ``normal`` out of the phantom),
    or a curved phantom's registered shape (then ``point`` and ``normal`` are its frame's
    origin and +z in the lab)."""

    point: np.ndarray
    normal: np.ndarray
    registration: Registration | None = None
    shape: Shape | None = None
    source: str = ""

    @property
    def curved(self) -> Curved | None:
        """A curved phantom's registration and shape; None for a flat one (its plane)."""
        if self.registration is None and self.shape is None:
            return None
        if self.registration is None or self.shape is None:
            raise ValueError("a curved rest surface needs its registration and its shape")
        return Curved(self.registration, self.shape)

    def depth(self, tip: np.ndarray) -> np.ndarray:
        """The tip's depth (T,) below the surface (into the phantom: +)."""
        curved = self.curved
        if curved is None:
            return tip_depth(tip, self.point, self.normal)
        return shape_depth(tip, curved.registration, curved.shape)

    def touches(self, tip: np.ndarray, depth: np.ndarray, presses: list[Press]
                ) -> tuple[np.ndarray, np.ndarray]:
        """Where each press touched the surface (P, 3) and its outward normal there (P, 3);
        ``depth`` (T,) is :meth:`depth` of ``tip``."""
        curved = self.curved
        if curved is None:
            return (contact_points(tip, presses, self.point, self.normal),
                    np.tile(self.normal, (len(presses), 1)))
        return shape_touches(tip, depth, presses, curved.registration, curved.shape,
                             self.source)


def rest_of(phantom: np.ndarray, cluster: np.ndarray, tip: np.ndarray, names: list[str],
            layout: PhantomLayout, source: str) -> RestSurface:
    """The phantom's rest surface: its plane, or its shape registered to the markers."""
    if layout.shape is None:
        return RestSurface(*rest_surface(phantom, cluster, tip, source))
    reg = register_markers(phantom, mean_seen(cluster) - tip, list(names), layout, source)
    to_lab = np.linalg.inv(reg.to_shape)
    return RestSurface(to_lab[:3, 3], to_lab[:3, 2], reg, layout.shape, str(source))


def tip_depth(tip: np.ndarray, point: np.ndarray, normal: np.ndarray) -> np.ndarray:
    """Depth (T,) of the tip below the plane through ``point`` along ``normal`` (+: inside)."""
    return (point - tip) @ normal


def contact_points(tip: np.ndarray, presses: list[Press], point: np.ndarray,
                   normal: np.ndarray, frames: int = 10) -> np.ndarray:
    """Where each press touched: the tip over its first loaded frames, on the rest plane."""
    return np.array([c - ((c - point) @ normal) * normal
                     for c in onset_tips(tip, presses, frames)]).reshape(-1, 3)


def onset_tips(tip: np.ndarray, presses: list[Press], frames: int = 10) -> np.ndarray:
    """The tip (P, 3) as each press began: its median over the first loaded ``frames`` seen.

    The onset, not the peak: a tilted press slides the tip sideways as it sinks in.
    """
    out = np.full((len(presses), 3), np.nan)
    for k, pr in enumerate(presses):
        seg = tip[pr.onset:min(pr.onset + frames, pr.release)]
        seg = seg[np.isfinite(seg).all(axis=1)]
        if len(seg) == 0:
            seg = tip[pr.onset:pr.release]
            seg = seg[np.isfinite(seg).all(axis=1)][:frames]
        if len(seg):
            out[k] = np.median(seg, axis=0)
    return out


def shape_depth(tip: np.ndarray, reg: Registration, shape: Shape) -> np.ndarray:
    """Depth (T,) of the tip inside the registered shape: minus its signed distance to the
    surface (NaN where the tip is not seen); exact within :data:`EXACT_DEPTH_M` of it, where
    the touches are found (a press's own depth runs along its normal: :func:`along_normals`)."""
    out = np.full(len(tip), np.nan)
    seen = np.isfinite(tip).all(axis=1)
    out[seen] = -shape.closest(_apply(reg.to_shape, tip[seen]), EXACT_DEPTH_M)[2]
    return out


def shape_touches(tip: np.ndarray, depth: np.ndarray, presses: list[Press], reg: Registration,
                  shape: Shape, source: str) -> tuple[np.ndarray, np.ndarray]:
    """Where each press touched the registered shape (P, 3) and its outward normal there
    (P, 3), both in the lab: where the tip's ``depth`` (T,) below the surface last crossed 0
    before the press's onset (between the two frames around it), or, where the tip was not
    seen outside, its onset position moved onto the surface. A press whose tip stays
    :data:`TOUCH_OFF_M` outside the surface as its force rises is refused by number.

    The crossing, not the onset: by the onset a tilted tip has slid along the surface, and on
    a curved one the normal turns with it."""
    start = onset_tips(tip, presses)
    seen = np.isfinite(start).all(axis=1)
    off = np.zeros(len(presses))
    off[seen] = shape.closest(_apply(reg.to_shape, start[seen]))[2]
    for k in np.flatnonzero(off > TOUCH_OFF_M):
        raise BadInput(source, f"press {k} (frame {presses[k].onset}): its tip is "
                               f"{off[k] * 1e3:.1f} mm outside the registered shape as the "
                               "force rises: it never touches the phantom")
    after = [0] + [pr.release for pr in presses[:-1]]      # never into the press before
    cross = np.array([_crossing(tip, depth, pr.onset, a)
                      for pr, a in zip(presses, after, strict=True)]).reshape(-1, 3)
    cross = np.where(np.isfinite(cross), cross, start)
    ok = np.isfinite(cross).all(axis=1)
    at, normal = np.full_like(cross, np.nan), np.full_like(cross, np.nan)
    if ok.any():
        back = np.linalg.inv(reg.to_shape)
        on, n, _ = shape.closest(_apply(reg.to_shape, cross[ok]))
        at[ok], normal[ok] = _apply(back, on), n @ back[:3, :3].T
    return at, normal


def _crossing(tip: np.ndarray, depth: np.ndarray, onset: int, start: int = 0) -> np.ndarray:
    """The tip where its depth last rose through 0 between frames ``start`` and ``onset``
    (NaN: not seen there)."""
    outside = start + np.flatnonzero(depth[start:onset + 1] <= 0)
    if outside.size == 0:
        return np.full(3, np.nan)
    i = int(outside[-1])
    after = i + 1 + np.flatnonzero(np.isfinite(depth[i + 1:onset + 1]))
    if after.size == 0:
        return tip[i]
    j = int(after[0])
    s = -depth[i] / (depth[j] - depth[i])
    return tip[i] + s * (tip[j] - tip[i])


def along_normals(records: list[PressRecord], touch: np.ndarray, normal: np.ndarray) -> None:
    """Each press's depth along its own surface normal from where it touched (set on the
    records, with that point and normal)."""
    for rec, c, n in zip(records, touch, normal, strict=True):
        rec.depth = (c - rec.points[:, -1]) @ n
        rec.touch, rec.touch_normal = c, n


def _apply(t: np.ndarray, p: np.ndarray) -> np.ndarray:
    return p @ t[:3, :3].T + t[:3, 3]

"""What lies inside the phantom: a label volume in the phantom frame (NIfTI), and each label's
stiffness.

session.toml's ``[phantom]`` names it, and ``[phantom.labels]`` gives each label's stiffness
ratio to the block's silicone (label 0), or ``"fit"`` to have ``pipeline fit-solid`` find it::

    [phantom]
    interior = "interior.nii.gz"     # a label map: 0 the block, 1..K inclusions or layers
    [phantom.labels]
    1 = 3.0                          # three times as stiff as the block
    2 = "fit"

The volume (``.nii`` / ``.nii.gz``, read with nibabel) holds whole labels; its affine maps a
voxel's indices to millimetres in the phantom frame of the states (the footprint on
[0, L] x [0, W], the rest surface at z = 0, +z out of the phantom), as a CT registered to the
markers would. A CT's own intensities may stand in for the labels, with a table that gives each
label its range of values, [low, high)::

    [phantom.intensities]
    0 = [-100.0, 150.0]              # the block's silicone
    1 = [150.0, 600.0]               # the inclusion

Refused in one line: a file nibabel cannot read, a volume that is not 3-D, NaN, a label that is
not a whole number >= 0 (without a table), a voxel in no range or ranges that overlap (with
one), a label without a ratio (or a ratio for a label the volume lacks), a ratio outside
:data:`RATIO`, and a volume that does not cover the block.
"""

from __future__ import annotations

import gzip
from collections.abc import Mapping
from dataclasses import dataclass
from pathlib import Path

import nibabel as nib
import numpy as np

from core.bounds import Bound
from core.errors import BadInput
from data_schema.phantom import phantom_table

RATIO = Bound(0.1, 20.0, why="a label's stiffness to the block's silicone")
GZIP = b"\x1f\x8b"            # a gzipped file's first bytes
FIT = "fit"                  # [phantom.labels] value: the ratio is fitted
COVER_TOL_M = 0.5e-3         # a volume may fall short of the block's faces by this much
FOOTPRINT_TOL_M = 5e-3       # and may reach past the footprint by at most this much


@dataclass(frozen=True)
class Interior:
    """A label volume: labels (I, J, K) and the affine from voxel indices to mm."""

    labels: np.ndarray
    affine: np.ndarray       # (4, 4) voxel (i, j, k, 1) -> mm (x, y, z, 1)

    def label_at(self, points: np.ndarray) -> np.ndarray:
        """(P,) the label of the voxel holding each (P, 3) point (m); -1 outside the volume."""
        homo = np.c_[np.asarray(points, float) * 1e3, np.ones(len(points))]
        ijk = np.rint((np.linalg.inv(self.affine) @ homo.T)[:3].T).astype(np.int64)
        inside = np.all((ijk >= 0) & (ijk < np.array(self.labels.shape)), axis=1)
        out = np.full(len(points), -1, dtype=np.int64)
        i, j, k = ijk[inside].T
        out[inside] = self.labels[i, j, k]
        return out

    def extent_m(self) -> tuple[np.ndarray, np.ndarray]:
        """The lowest and highest corner of the voxels (m, phantom frame)."""
        n = np.array(self.labels.shape)
        corners = np.array([[a, b, c, 1.0] for a in (-0.5, n[0] - 0.5)
                            for b in (-0.5, n[1] - 0.5) for c in (-0.5, n[2] - 0.5)])
        mm = (self.affine @ corners.T)[:3].T
        return mm.min(axis=0) * 1e-3, mm.max(axis=0) * 1e-3

    def present(self) -> list[int]:
        """The labels the volume holds, ascending."""
        return [int(v) for v in np.unique(self.labels)]


def read_interior(path: str | Path, intensities: Mapping[str, object] | None = None
                  ) -> Interior:
    """The label volume at ``path``, checked (one line naming it where it is not one); with
    ``intensities`` (``[phantom.intensities]``: label -> [low, high)), a volume of intensities
    turned into labels by that table."""
    path = Path(path)
    data, affine = _read_volume(path)
    if intensities is not None:
        return Interior(labels=labels_from_intensities(data, intensities, path), affine=affine)
    if np.any(data < 0) or np.any(data != np.rint(data)):
        raise BadInput(path, "labels must be whole numbers >= 0 (0 the block's silicone); a "
                             "CT's intensities need a [phantom.intensities] table")
    return Interior(labels=data.astype(np.int64), affine=affine)


def labels_from_intensities(data: np.ndarray, table: Mapping[str, object], path: str | Path
                            ) -> np.ndarray:
    """Each voxel's label from its intensity: the label whose [low, high) holds it. Refused
    where a range is not two increasing numbers, where two ranges overlap, or where a voxel
    falls in none (how many, and their lowest and highest value)."""
    ranges = sorted((_range(value, key, path) + (int(key),) for key, value in table.items()))
    for (_, high, a), (low, _, b) in zip(ranges, ranges[1:], strict=False):
        if low < high:
            raise BadInput(path, f"[phantom.intensities] ranges of labels {a} and {b} overlap")
    out = np.full(data.shape, -1, dtype=np.int64)
    for low, high, label in ranges:
        out[(data >= low) & (data < high)] = label
    loose = data[out < 0]
    if loose.size:
        raise BadInput(path, f"{loose.size} voxel(s) fall in no [phantom.intensities] range "
                             f"(values {loose.min():g} to {loose.max():g})")
    return out


def _range(value: object, key: object, path: str | Path) -> tuple[float, float]:
    """A label's intensity range [low, high), checked."""
    if not (isinstance(key, str) and key.isdigit()):
        raise BadInput(path, f"[phantom.intensities] key {key!r} is not a label number")
    if not (isinstance(value, list) and len(value) == 2 and all(
            isinstance(v, int | float) and not isinstance(v, bool) and np.isfinite(v)
            for v in value)) or not value[0] < value[1]:
        raise BadInput(path, f"[phantom.intensities] label {key} = {value!r}: a range must be "
                             "[low, high] with low < high")
    return float(value[0]), float(value[1])


def _read_volume(path: Path) -> tuple[np.ndarray, np.ndarray]:
    """A 3-D volume's finite values and its affine (mm), or one line naming the file."""
    try:
        raw = path.read_bytes()
        image = nib.Nifti1Image.from_bytes(gzip.decompress(raw) if raw[:2] == GZIP else raw)
        data = np.asarray(image.dataobj, dtype=np.float64)
        affine = np.asarray(image.affine, dtype=np.float64)
    except Exception as e:          # nibabel raises many kinds for a file it cannot read
        raise BadInput(path, f"not a NIfTI volume nibabel can read ({type(e).__name__}: "
                             f"{str(e).splitlines()[0] if str(e) else 'unreadable'})") from None
    if data.ndim != 3:
        raise BadInput(path, f"the interior must be a 3-D label volume, not {data.ndim}-D")
    if not np.isfinite(data).all():
        raise BadInput(path, f"{int((~np.isfinite(data)).sum())} voxel(s) are NaN or infinite")
    if not np.isfinite(affine).all() or abs(np.linalg.det(affine[:3, :3])) < 1e-12:
        raise BadInput(path, "its affine is singular or not finite")
    return data, affine


def write_interior(path: str | Path, labels: np.ndarray, affine: np.ndarray) -> None:
    """Write ``labels`` (I, J, K) with ``affine`` (mm) as gzipped NIfTI-1 (the bytes the same
    for the same volume: no time stamp), whatever the path's name (a temporary one)."""
    image = nib.Nifti1Image(np.asarray(labels, dtype=np.uint8), np.asarray(affine, float))
    image.header.set_xyzt_units("mm")
    Path(path).write_bytes(gzip.compress(image.to_bytes(), mtime=0))


def check_covers(interior: Interior, path: str | Path, lower: np.ndarray, upper: np.ndarray
                 ) -> None:
    """Refuse a volume that does not cover the block (its box from the ``lower`` to the
    ``upper`` corner, m) or whose extent disagrees with the footprint (its affine in other
    units or frame)."""
    lo, hi = interior.extent_m()
    want_lo, want_hi = np.asarray(lower, dtype=float), np.asarray(upper, dtype=float)
    footprint = want_hi[:2] - want_lo[:2]
    short = np.maximum(lo - want_lo, want_hi - hi)
    if np.any(short > COVER_TOL_M):
        axis = "xyz"[int(np.argmax(short))]
        raise BadInput(path, f"the volume does not cover the block: it spans "
                             f"{_span(lo, hi)} mm, the block {_span(want_lo, want_hi)} mm "
                             f"(short by {short.max() * 1e3:.1f} mm along {axis})")
    past = np.maximum(want_lo[:2] - lo[:2], hi[:2] - want_hi[:2])
    if np.any(past > FOOTPRINT_TOL_M):
        raise BadInput(path, f"its affine disagrees with the footprint "
                             f"{footprint[0] * 1e3:g} x {footprint[1] * 1e3:g} mm: the volume "
                             f"spans {_span(lo, hi)} mm (is it in mm, in the phantom frame?)")


def label_ratios(table: Mapping[str, object] | None, present: list[int], path: str | Path
                 ) -> dict[int, float | None]:
    """``[phantom.labels]`` checked against the labels ``present``: label -> ratio (None:
    fitted); label 0 (the block) is 1 and needs no entry."""
    table = dict(table or {})
    out: dict[int, float | None] = {0: 1.0}
    for key, value in table.items():
        if not (isinstance(key, str) and key.isdigit()):
            raise BadInput(path, f"[phantom.labels] key {key!r} is not a label number")
        label = int(key)
        if label not in present:
            raise BadInput(path, f"[phantom.labels] gives label {label} a ratio, but the "
                                 f"interior has only labels {present}")
        out[label] = _ratio(value, label, path)
    missing = [k for k in present if k not in out]
    if missing:
        raise BadInput(path, f"label {missing[0]} of the interior has no ratio in "
                             "[phantom.labels] (a number, or \"fit\")")
    return out


@dataclass(frozen=True)
class InteriorSpec:
    """A session's interior: the volume and each label's ratio (None: to be fitted)."""

    path: Path
    interior: Interior
    ratios: dict[int, float | None]


def session_interior(folder: str | Path) -> InteriorSpec | None:
    """The interior a session folder's ``session.toml`` names (None: it names none)."""
    toml, phantom = phantom_table(folder)
    name = phantom.get("interior")
    if name is None:
        for key in ("labels", "intensities"):
            if key in phantom:
                raise BadInput(toml, f"[phantom.{key}] without [phantom] interior")
        return None
    if not isinstance(name, str):
        raise BadInput(toml, f"phantom.interior must name a file, got {name!r}")
    path = Path(folder) / name
    if not path.is_file():
        raise BadInput(toml, f"phantom.interior names {name!r}, which does not exist")
    table = phantom.get("intensities")
    if table is not None and not isinstance(table, dict):
        raise BadInput(toml, "[phantom.intensities] must be a table of label = [low, high]")
    interior = read_interior(path, table)
    labels = phantom.get("labels")
    if labels is not None and not isinstance(labels, dict):
        raise BadInput(toml, "[phantom.labels] must be a table of label = ratio")
    return InteriorSpec(path, interior, label_ratios(labels, interior.present(), toml))


def _ratio(value: object, label: int, path: str | Path) -> float | None:
    """A label's ratio: a number within :data:`RATIO`, or ``"fit"`` (None)."""
    if value == FIT:
        return None
    if (not isinstance(value, int | float) or isinstance(value, bool)
            or not np.isfinite(value) or not RATIO.holds(float(value))):
        raise BadInput(path, f"[phantom.labels] label {label} = {value!r}: a ratio must be "
                             f"{RATIO.describe()}, or \"fit\"")
    return float(value)


def _span(lo: np.ndarray, hi: np.ndarray) -> str:
    return " x ".join(f"[{a * 1e3:.1f}, {b * 1e3:.1f}]" for a, b in zip(lo, hi, strict=True))

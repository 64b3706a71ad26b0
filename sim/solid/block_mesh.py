"""The block as hexahedra: a tensor grid over the footprint and the thickness, finer at the top.

The phantom frame of a states file puts the rest surface at z = 0 through the markers' centres;
the silicone's top lies a marker's radius below it (``top_z``, where the tip rests). The mesh
spans ``[0, L] x [0, W] x [top_z - thickness, top_z]``: its bottom face is the table's, held
fixed. Across, the nodes are ``spacing`` apart (the lattice a 5 mm grid of places lands on);
through the thickness the layers are thinner at the top, where the presses strain it most.

A curved phantom's block is its shape (:mod:`data_schema.shape`, in its own frame): the same
grid over the shape's extent in x and y, each column of nodes stretched from the table (the
shape's lowest z) to its top surface, the layers keeping their shares of the column (a mould
standing on its base, whose top is one surface over its footprint).
"""

from __future__ import annotations

from dataclasses import dataclass, field

import numpy as np
from skfem import MeshHex

from core.bounds import Bound
from core.errors import BadInput
from data_schema.shape import Shape

SPACING = Bound(0.5e-3, 20e-3, unit="m")       # the nodes' spacing across the footprint
LAYERS = Bound(2, 40, whole=True)                        # element layers through the thickness
TOP_SHARE = 0.25                               # the top quarter of the block holds half the
#                                                layers (graded towards the surface)


@dataclass(frozen=True)
class BlockGeometry:
    """The block in the phantom frame (m): footprint (L, W), thickness, and its top's height."""

    footprint: tuple[float, float]
    thickness: float
    top_z: float = 0.0
    shape: Shape | None = field(default=None, compare=False)   # a curved top; None: flat

    @property
    def lower(self) -> np.ndarray:
        """(3,) the block's lowest corner: the footprint's origin on the table."""
        if self.shape is None:
            return np.array([0.0, 0.0, self.top_z - self.thickness])
        return self.shape.vertices.min(axis=0)

    @property
    def upper(self) -> np.ndarray:
        """(3,) the block's highest corner: the footprint's far corner at its top."""
        if self.shape is None:
            return np.array([*self.footprint, self.top_z])
        return self.shape.vertices.max(axis=0)

    def top(self, xy: np.ndarray) -> np.ndarray:
        """(P,) the top face's height over (P, 2) points."""
        xy = np.asarray(xy, dtype=np.float64).reshape(-1, 2)
        if self.shape is None:
            return np.full(len(xy), self.top_z)
        z = self.shape.height(np.clip(xy, self.lower[:2], self.upper[:2]))
        if not np.all(z > self.lower[2]):
            raise BadInput(None, "the shape's top does not cover its footprint (a mould "
                                 "standing on its base, one surface over its extent, is "
                                 "what the solid meshes)")
        return z

    def inside(self, points: np.ndarray, tol: float = 1e-9) -> np.ndarray:
        """(P,) bool: which (P, 3) points lie in the block."""
        L, W = self.footprint
        x, y, z = points[:, 0], points[:, 1], points[:, 2]
        return ((x >= -tol) & (x <= L + tol) & (y >= -tol) & (y <= W + tol)
                & (z >= self.top_z - self.thickness - tol) & (z <= self.top_z + tol))


def axis_nodes(length: float, spacing: float) -> np.ndarray:
    """Node coordinates on [0, length], as close to ``spacing`` apart as fits evenly."""
    n = max(1, int(round(length / spacing)))
    return np.linspace(0.0, length, n + 1)


def depth_nodes(thickness: float, layers: int) -> np.ndarray:
    """Node depths below the top, 0 .. thickness: half the ``layers`` in the top quarter."""
    top = max(1, layers // 2)
    upper = np.linspace(0.0, TOP_SHARE * thickness, top + 1)
    lower = np.linspace(TOP_SHARE * thickness, thickness, layers - top + 1)[1:]
    return np.concatenate([upper, lower])


def block_mesh(block: BlockGeometry, spacing: float, layers: int) -> MeshHex:
    """The hexahedral mesh of ``block``: ``spacing`` across, ``layers`` through."""
    if block.shape is not None:
        return _curved_mesh(block, spacing, layers)
    xs = axis_nodes(block.footprint[0], spacing)
    ys = axis_nodes(block.footprint[1], spacing)
    zs = np.sort(block.top_z - depth_nodes(block.thickness, layers))
    return MeshHex.init_tensor(xs, ys, zs)


def _curved_mesh(block: BlockGeometry, spacing: float, layers: int) -> MeshHex:
    """A curved block's mesh: the flat grid over the shape's extent, its columns stretched
    from the table to the top surface, each layer keeping its share of the column."""
    lo, hi = block.lower, block.upper
    xs = lo[0] + axis_nodes(hi[0] - lo[0], spacing)
    ys = lo[1] + axis_nodes(hi[1] - lo[1], spacing)
    share = np.sort(1.0 - depth_nodes(1.0, layers))                 # 0 (table) .. 1 (top)
    grid = MeshHex.init_tensor(xs, ys, share)
    p = grid.p.copy()
    p[2] = lo[2] + p[2] * (block.top(p[:2].T) - lo[2])
    return MeshHex(p, grid.t)


def graded_axis(length: float, fine: float, fine_until: float, growth: float) -> np.ndarray:
    """Nodes on [0, length]: ``fine`` apart up to ``fine_until``, then each gap ``growth``
    times the one before (a mesh fine where a contact is, coarse far from it)."""
    nodes, gap = [0.0], fine
    while nodes[-1] < length - 1e-12:
        if nodes[-1] >= fine_until - 1e-12:
            gap *= growth
        nodes.append(min(length, nodes[-1] + gap))
    if len(nodes) > 2 and nodes[-1] - nodes[-2] < 0.3 * gap:
        del nodes[-2]                                  # no sliver at the far face
    return np.array(nodes)

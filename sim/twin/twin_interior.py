"""The twin's interior as a CT would show it: a label volume at 1 mm voxels in the states'
phantom frame, and the labels' true ratios for session.toml.

The phantom frame of the states (extract's) puts the footprint's corner at the origin and the
rest surface at z = 0 through the markers' centres; the silicone's top lies a marker's radius
below it. Label 0 is the block's silicone, 1 the top layer where there is one, then one label
per inclusion (an inclusion inside the layer is the inclusion's). The volume spans the
footprint and the thickness below the silicone's top, with :data:`MARGIN_MM` above and below.
"""

from __future__ import annotations

import numpy as np

from sim.twin.phantom import PhantomSpec

VOXEL_MM = 1.0
MARGIN_MM = 2.0


def interior_volume(spec: PhantomSpec) -> tuple[np.ndarray, np.ndarray, dict[str, float]]:
    """The labels (I, J, K), the affine (voxel -> mm) and ``[phantom.labels]``'s table."""
    length, width, thickness = (s * 1e3 for s in spec.size)
    top = -spec.marker_radius * 1e3
    z0 = top - thickness - MARGIN_MM
    n = [int(round(length / VOXEL_MM)), int(round(width / VOXEL_MM)),
         int(round((thickness + 2 * MARGIN_MM) / VOXEL_MM))]
    affine = np.diag([VOXEL_MM, VOXEL_MM, VOXEL_MM, 1.0])
    affine[:3, 3] = [VOXEL_MM / 2, VOXEL_MM / 2, z0 + VOXEL_MM / 2]
    axes = [affine[a, 3] + VOXEL_MM * np.arange(n[a]) for a in range(3)]
    x, y, z = np.meshgrid(*axes, indexing="ij")
    depth = top - z                                        # mm below the silicone's top
    labels = np.zeros(n, dtype=np.uint8)
    table: dict[str, float] = {}
    if spec.layer is not None:
        labels[(depth >= 0) & (depth <= spec.layer.thickness * 1e3)] = 1
        table["1"] = float(spec.layer.ratio)
    for inc in spec.inclusions:
        k = len(table) + 1
        inside = ((x - inc.x * 1e3) ** 2 + (y - inc.y * 1e3) ** 2
                  + (depth - inc.depth * 1e3) ** 2) <= (inc.radius * 1e3) ** 2
        labels[inside & (depth >= 0) & (depth <= thickness)] = k
        table[str(k)] = float(inc.ratio)
    return labels, affine, table

"""Random force directions: uniform on the spherical cap around the inward normal (-z).

Both the MSM protocol (directions within 45 degrees of the normal) and the twin's hand
(press directions within 20 degrees) draw their directions here, so the distribution is
written once: ``cos(angle)`` uniform on ``[cos(max_angle), 1]`` (uniform over the cap's area),
azimuth uniform on ``[0, 2 pi)``.
"""

from __future__ import annotations

import math

import numpy as np


def cone_directions(rng: np.random.Generator, max_angle_deg: float,
                    size: int | tuple[int, ...] = ()) -> np.ndarray:
    """Unit vectors (``size`` + (3,)) within ``max_angle_deg`` of (0, 0, -1).

    Draws all the cosines first, then all the azimuths (one of each for ``size=()``).
    """
    cos_t = rng.uniform(math.cos(math.radians(max_angle_deg)), 1.0, size)
    phi = rng.uniform(0.0, 2 * math.pi, size)
    sin_t = np.sqrt(1.0 - cos_t ** 2)
    return np.stack([sin_t * np.cos(phi), sin_t * np.sin(phi), -cos_t], -1)

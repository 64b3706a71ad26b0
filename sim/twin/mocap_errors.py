"""What the cameras do to true marker positions: residual noise and occlusion gaps.

Noise: each sample is displaced in a uniformly random direction by a distance drawn from a
gamma distribution whose mean and standard deviation are the paper's residual, 0.18 +- 0.22 mm
(shape (m/s)^2 = 0.67, scale s^2/m = 0.27 mm): most samples are within a tenth of a millimetre,
a few are off by a millimetre. Samples are independent from frame to frame.

Gaps: each marker loses sight in bursts that start at random (a Poisson process) and last
6-50 ms, 15 % of them (``long_share``) 0.1-0.4 s. Bursts start far more often when the hand
is near: on the indenter's markers when the tip is within 40 mm of the surface, and on the
phantom markers within 25 mm of the tip when it is that close.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np


@dataclass(frozen=True)
class MocapErrors:
    """Noise and occlusion settings (metres, seconds, gap starts per second)."""

    residual_mean: float = 0.18e-3
    residual_sd: float = 0.22e-3
    short_gap_s: tuple[float, float] = (0.006, 0.050)
    long_gap_s: tuple[float, float] = (0.100, 0.400)
    long_share: float = 0.15
    indenter_rate: float = 0.15        # gap starts per second, hand away
    indenter_near_rate: float = 0.6    # ... tip near the surface
    phantom_rate: float = 0.01
    phantom_near_rate: float = 0.8     # phantom markers near the tip
    near_height: float = 0.040
    near_radius: float = 0.025


def residual_noise(rng: np.random.Generator, shape: tuple[int, ...],
                   errors: MocapErrors) -> np.ndarray:
    """Displacements (``shape`` + (3,)) with gamma-distributed lengths, random directions."""
    m, s = errors.residual_mean, errors.residual_sd
    length = rng.gamma((m / s) ** 2, s * s / m, shape)
    direction = rng.normal(size=shape + (3,))
    direction /= np.linalg.norm(direction, axis=-1, keepdims=True)
    return length[..., None] * direction


def gap_mask(rng: np.random.Generator, rate: np.ndarray, frame_rate: float,
             errors: MocapErrors) -> np.ndarray:
    """(T, M) True where a marker is visible, given gap-start rates (T, M) per second."""
    starts = np.argwhere(rng.random(rate.shape) < rate / frame_rate)
    long = rng.random(len(starts)) < errors.long_share
    seconds = np.where(long, rng.uniform(*errors.long_gap_s, len(starts)),
                       rng.uniform(*errors.short_gap_s, len(starts)))
    lengths = np.maximum(1, np.round(seconds * frame_rate)).astype(np.int64)
    visible = np.ones(rate.shape, dtype=bool)
    for (t, m), n in zip(starts, lengths, strict=True):
        visible[t:t + n, m] = False
    return visible


def gap_rates(tip: np.ndarray, surface_height: np.ndarray, phantom_rest: np.ndarray,
              n_indenter: int, errors: MocapErrors) -> np.ndarray:
    """(T, N + n_indenter) gap-start rates from the tip (T, 3) and its height above the rest
    surface (T,); ``phantom_rest`` (N, 3) are the N phantom markers at rest (lab)."""
    near = surface_height < errors.near_height
    close = np.linalg.norm(tip[:, None, :2] - phantom_rest[None, :, :2], axis=2)
    phantom = np.where(near[:, None] & (close < errors.near_radius),
                       errors.phantom_near_rate, errors.phantom_rate)
    indenter = np.where(near, errors.indenter_near_rate, errors.indenter_rate)
    return np.concatenate([phantom, np.repeat(indenter[:, None], n_indenter, axis=1)], axis=1)

"""QTM's 6D body as the twin writes it: the body definition fitted to the measured markers.

QTM's 6DOF solver places the body definition on the markers it measured in each frame (least
squares, at least 3 of them), so its 6D export carries the markers' noise and is lost where
fewer than 3 are seen. The twin does the same with its own few lines, not with the cluster fit
of :mod:`sync`: it is there to check that stage against the truth, so it shares none of its
code. Frames are fitted in groups that see the same markers, each group in one batched SVD.
"""

from __future__ import annotations

import numpy as np


def qtm_body(body: np.ndarray, measured: np.ndarray
             ) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """The 6D body of ``body`` (M, 3) markers fitted to ``measured`` (T, M, 3), NaN unseen.

    Returns the body origin (T, 3) and rotation (T, 3, 3) in the lab (``lab = R body + o``)
    and the residual (T,): the RMS distance of the seen markers from the fitted body, in
    metres; NaN in frames with fewer than 3 markers seen (QTM writes those lost).
    """
    frames = len(measured)
    origin = np.full((frames, 3), np.nan)
    rotation = np.full((frames, 3, 3), np.nan)
    residual = np.full(frames, np.nan)
    seen = np.isfinite(measured).all(axis=2)
    for pattern in np.unique(seen[seen.sum(axis=1) >= 3], axis=0):
        rows = np.flatnonzero((seen == pattern).all(axis=1))
        rot, org, rms = _kabsch(body[pattern], measured[rows][:, pattern])
        origin[rows], rotation[rows], residual[rows] = org, rot, rms
    return origin, rotation, residual


def _kabsch(ref: np.ndarray, obs: np.ndarray) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Rotations (F, 3, 3), origins (F, 3) and RMS residuals (F,) that best map the points
    ``ref`` (K, 3) onto each frame of ``obs`` (F, K, 3)."""
    ref_mean, obs_mean = ref.mean(axis=0), obs.mean(axis=1)
    cross = np.einsum("ki,fkj->fij", ref - ref_mean, obs - obs_mean[:, None])
    u, _, vt = np.linalg.svd(cross)
    flip = np.where(np.linalg.det(u) * np.linalg.det(vt) < 0, -1.0, 1.0)
    vt[:, 2] *= flip[:, None]                        # a rotation, never a reflection
    rot = np.einsum("fji,fkj->fik", vt, u)          # V U^T
    org = obs_mean - rot @ ref_mean
    fitted = np.einsum("fij,kj->fki", rot, ref) + org[:, None]
    rms = np.sqrt(((obs - fitted) ** 2).sum(axis=2).mean(axis=1))
    return rot, org, rms

"""Rigid-body fit of a marker cluster (the indenter) frame by frame.

Least-squares rotation and translation (Kabsch/SVD) that map the cluster's reference shape, in
its body frame, onto the markers seen in each frame. Three of four markers suffice; frames with
fewer, with nearly collinear visible markers, or with a large residual are flagged rather than
trusted.
"""

from __future__ import annotations

from dataclasses import dataclass
from pathlib import Path

import numpy as np

from core.errors import BadInput


@dataclass
class RigidFit:
    """Per-frame pose of a cluster: ``lab = rotation @ body + translation``."""

    rotation: np.ndarray     # (T, 3, 3) body -> lab; NaN where no fit
    translation: np.ndarray  # (T, 3) metres; NaN where no fit
    rms: np.ndarray          # (T,) residual RMS over the used markers, metres; NaN where no fit
    n_markers: np.ndarray    # (T,) int, markers used
    ill_conditioned: np.ndarray  # (T,) bool: visible markers nearly collinear
    poor: np.ndarray         # (T,) bool: ill-conditioned or residual above the limit

    @property
    def valid(self) -> np.ndarray:
        """Frames with a pose (at least 3 markers), poor or not."""
        return self.n_markers >= 3

    def apply(self, body_point: np.ndarray) -> np.ndarray:
        """A body-frame point (3,) in the lab frame per frame, (T, 3); NaN where no fit."""
        return self.rotation @ np.asarray(body_point, float) + self.translation

    def apply_all(self, body_points: np.ndarray) -> np.ndarray:
        """Body-frame points (M, 3) in the lab frame per frame, (T, M, 3)."""
        return np.einsum("tij,mj->tmi", self.rotation, np.asarray(body_points, float)) + \
            self.translation[:, None]


def fit_rigid(
    reference: np.ndarray,
    observed: np.ndarray,
    max_rms: float,
    min_spread_ratio: float = 0.1,
    drop_outlier: bool = True,
    robust_scale: float | None = None,
) -> RigidFit:
    """Fit the reference cluster (M, 3) to each frame of ``observed`` (T, M, 3), NaN = unseen.

    A frame is fitted when at least 3 markers are seen. It is ``ill_conditioned`` when the seen
    reference markers are nearly collinear (second principal spread below ``min_spread_ratio``
    of the first), and ``poor`` when ill-conditioned or its RMS residual exceeds ``max_rms``.
    With ``drop_outlier``, a poor frame of 4 or more markers is refitted without each marker in
    turn, and of the refits that are well conditioned and within ``max_rms`` the one with the
    smallest residual replaces it (a mislabelled or ghost marker is then ignored rather than
    spoiling the pose). With ``robust_scale`` (m),
    the fit is iteratively reweighted with Cauchy weights ``1 / (1 + (r / scale)^2)`` of each
    marker's residual ``r``, so a marker far off in a heavy-tailed noise draw pulls less.
    """
    fit = _fit(reference, observed, max_rms, min_spread_ratio)
    if robust_scale:
        for _ in range(2):
            r = np.linalg.norm(observed - fit.apply_all(reference), axis=2)
            weights = 1.0 / (1.0 + (np.nan_to_num(r) / robust_scale) ** 2)
            fit = _fit(reference, observed, max_rms, min_spread_ratio, weights)
    if not drop_outlier:
        return fit
    obs = np.asarray(observed, float)
    redo = np.flatnonzero(fit.poor & (fit.n_markers >= 4))
    if redo.size == 0:
        return fit
    best = np.full(redo.size, np.inf)
    for m in range(obs.shape[1]):
        trial = obs[redo].copy()
        trial[:, m] = np.nan
        alt = fit_rigid(reference, trial, max_rms, min_spread_ratio, False, robust_scale)
        better = ~alt.poor & (alt.n_markers >= 3) & (alt.rms < best)
        for name in ("rotation", "translation", "rms", "n_markers", "ill_conditioned", "poor"):
            getattr(fit, name)[redo[better]] = getattr(alt, name)[better]
        best[better] = alt.rms[better]
    return fit


def _fit(reference: np.ndarray, observed: np.ndarray, max_rms: float,
         min_spread_ratio: float, weights: np.ndarray | None = None) -> RigidFit:
    """One weighted least-squares fit per frame over the seen markers (see :func:`fit_rigid`).

    ``weights`` (T, M) default to 1 for every seen marker; the RMS residual is unweighted.
    """
    ref = np.asarray(reference, float)
    obs = np.asarray(observed, float)
    if obs.ndim != 3 or obs.shape[1:] != ref.shape or ref.shape[1] != 3:
        raise ValueError(f"observed {obs.shape} does not match reference {ref.shape}")
    seen = np.isfinite(obs).all(axis=2)                       # (T, M)
    n = seen.sum(axis=1)                                       # (T,)
    ok = n >= 3
    w = seen.astype(float) if weights is None else np.where(seen, weights, 0.0)
    w_sum = np.where(ok, w.sum(axis=1), 1.0)[:, None]
    obs0 = np.where(seen[..., None], obs, 0.0)
    c_ref = (w @ ref) / w_sum                                  # (T, 3) weighted centroids
    c_obs = np.matmul(w[:, None, :], obs0)[:, 0] / w_sum
    p = ref[None] - c_ref[:, None]                             # (T, M, 3) centred
    q = obs0 - c_obs[:, None]
    h = np.matmul((p * w[..., None]).transpose(0, 2, 1), q)  # weighted cross-covariance
    u, _, vt = np.linalg.svd(h)
    d = np.sign(np.linalg.det(u) * np.linalg.det(vt))
    d = np.where(d == 0, 1.0, d)
    fix = np.ones((len(d), 3))
    fix[:, 2] = d
    rot = np.matmul(vt.transpose(0, 2, 1) * fix[:, None], u.transpose(0, 2, 1))  # V D U^T
    trans = c_obs - np.matmul(rot, c_ref[..., None])[..., 0]
    resid = obs0 - (np.matmul(ref, rot.transpose(0, 2, 1)) + trans[:, None])
    sq = (resid**2).sum(axis=2) * seen
    rms = np.sqrt(sq.sum(axis=1) / np.where(ok, n, 1))
    ps = p * seen[..., None]
    lam = np.linalg.eigvalsh(np.matmul(ps.transpose(0, 2, 1), ps))  # ascending
    spread = np.sqrt(np.clip(lam[:, ::-1], 0.0, None))               # principal spreads
    ill = ok & (spread[:, 1] < min_spread_ratio * np.maximum(spread[:, 0], 1e-300))
    rot[~ok] = np.nan
    trans[~ok] = np.nan
    rms[~ok] = np.nan
    poor = ok & (ill | (rms > max_rms))
    return RigidFit(rot, trans, rms, n.astype(int), ill, poor)


def cluster_reference(
    observed: np.ndarray, source: str | Path | None = None, iterations: int = 3
) -> np.ndarray:
    """The cluster's shape (M, 3) in its own body frame, from frames where every marker is seen.

    Generalised Procrustes: align every complete frame to the current mean, average, repeat.
    The body frame has its origin at the markers' centroid and its axes along their principal
    directions (largest spread first), a right-handed frame whose signs the markers' order
    fixes (:func:`canonical_axes`), so every machine finds the same body frame.
    """
    obs = np.asarray(observed, float)
    complete = np.isfinite(obs).all(axis=(1, 2))
    if complete.sum() < 1:
        raise BadInput(source, "no frame shows every marker of the indenter cluster, "
                               "so its shape cannot be measured")
    frames = obs[complete]
    mean = frames[0] - frames[0].mean(axis=0)
    for _ in range(iterations):
        fit = fit_rigid(mean, frames, max_rms=np.inf)
        body = np.einsum("tji,tmj->tmi", fit.rotation, frames - fit.translation[:, None])
        mean = body.mean(axis=0)
        mean -= mean.mean(axis=0)
    return mean @ canonical_axes(mean).T


def canonical_axes(points: np.ndarray, rel_tol: float = 1e-6) -> np.ndarray:
    """Principal axes (3, 3, rows) of centred points (M, 3), their signs fixed by the data.

    An SVD leaves each axis' sign to LAPACK (it differs between BLAS kernels). Here the first
    two axes point so that the first marker, in the markers' order, with a clear projection on
    the axis lies on its positive side, and the third is their cross product: the same
    right-handed frame on every machine for the same input.
    """
    _, s, vt = np.linalg.svd(points)
    axes = vt.copy()
    for a in range(2):
        proj = points @ axes[a]
        clear = np.flatnonzero(np.abs(proj) > rel_tol * max(s[0], 1e-300))
        if clear.size and proj[clear[0]] < 0:
            axes[a] = -axes[a]
    axes[2] = np.cross(axes[0], axes[1])
    return axes

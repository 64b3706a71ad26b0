"""The indenter tip in every mocap frame, the last point of a synced record.

The tip offset comes from the pivot recording (the cluster swung about the tip held in a
divot); the cluster's pose is then fitted in every trial frame (3 of 4 markers suffice, robustly
reweighted, poor or ill-conditioned fits flagged and dropped) and carries the tip. A session
whose indenter is almost never tracked, or a press with no usable pose, is refused: the tip
would be unknown.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from calib.pivot import PivotResult, pivot_calibrate
from calib.rigid import RigidFit, cluster_reference, fit_rigid
from core.errors import BadInput
from core.series import RawSession
from sync.presses import Press
from sync.sync_params import SyncParams

MIN_TRACKED = 0.05               # least fraction of frames with a usable indenter pose


@dataclass
class TipTrack:
    """The indenter's body frame, its tip offset, its pose per frame and the tip it carries."""

    cluster_body: np.ndarray     # (M, 3) indenter markers in the body frame
    pivot: PivotResult
    pose: RigidFit               # per trial frame
    tip: np.ndarray              # (T, 3) lab frame; NaN where the pose is missing or poor


def track_tip(raw: RawSession, p: SyncParams) -> TipTrack:
    """Calibrate the tip from the pivot recording and follow it through the trial."""
    ref, pivot = pivot_tip(raw, p)
    cluster = raw.markers.select(raw.indenter_markers)
    pose = fit_rigid(ref, cluster, max_rms=p.max_fit_rms_m, robust_scale=p.robust_scale_m)
    check_tracked(raw, pose)
    tip = pose.apply(pivot.tip_body)
    tip[pose.poor] = np.nan
    return TipTrack(ref, pivot, pose, tip)


def pivot_tip(raw: RawSession, p: SyncParams) -> tuple[np.ndarray, PivotResult]:
    """The cluster's body frame and the tip offset in it, from the pivot recording."""
    if raw.pivot is None:
        raise BadInput(raw.markers.source, "no pivot recording in the session: the tip offset "
                                           "of the indenter is unknown")
    cluster = raw.pivot.select(raw.indenter_markers)
    ref = cluster_reference(cluster, raw.pivot.source)
    fit = fit_rigid(ref, cluster, max_rms=p.max_fit_rms_m, robust_scale=p.robust_scale_m)
    good = fit.valid & ~fit.poor
    res = pivot_calibrate(fit.rotation[good], fit.translation[good], raw.pivot.source,
                          min_rotation_deg=p.min_pivot_rotation_deg)
    return ref, res


def check_tracked(raw: RawSession, pose: RigidFit) -> None:
    """Refuse a session whose indenter has a usable pose in almost no frame."""
    usable = pose.valid & ~pose.poor
    if usable.mean() < MIN_TRACKED:
        raise BadInput(raw.markers.source, f"the indenter has a usable pose in only "
                                           f"{int(usable.sum())} of {len(usable)} frames "
                                           f"({int(pose.poor.sum())} fits poor): are its "
                                           "markers labelled as in the pivot recording?")


def check_cluster(raw: RawSession, pose: RigidFit, presses: list[Press]) -> None:
    """Every press needs a usable pose (3 markers seen and a fit that is not poor)."""
    for k, pr in enumerate(presses):
        span = slice(pr.onset, pr.release)
        if (pose.valid[span] & ~pose.poor[span]).any():
            continue
        what = ("fewer than 3 indenter markers seen through the whole press" if
                not pose.valid[span].any() else "every indenter fit through the whole press "
                "is poor (markers mislabelled, or a ghost marker?)")
        raise BadInput(raw.markers.source, f"press {k}: {what}, so the tip is unknown",
                       where=f"frames {pr.onset}-{pr.release - 1}")

"""Calibration before the first press, with the code sync uses: the tip, and the force's tare.

- The tip: from the session's pivot recording (:func:`sync.tip_track.pivot_tip`, the cluster
  swung about the tip held in a divot), or from an earlier sync's results (``--calibration
  X.h5``: its ``calibration/cluster_body`` and ``calibration/tip_body``). Known before QTM is
  asked for a frame: a session without either is refused at once.
- The tare: the force's bias over its unloaded start (:func:`calib.force_tare.unloaded_start`,
  the first seconds before anything touches the sensor), taken once that much has arrived.
Each is refused in one line when it cannot be trusted, as sync refuses it.
"""

from __future__ import annotations

from dataclasses import dataclass
from pathlib import Path

import numpy as np

from calib.force_tare import Tare, apply_calibration, unloaded_start
from calib.rigid import fit_rigid
from core.errors import BadInput
from core.series import RawSession
from data_schema.hdf5 import read_h5
from data_schema.session import SessionConfig
from data_schema.synced import SYNCED
from ingest.detect import read_mocap
from live.session.layout import LiveLayout
from sync.sync_params import SyncParams
from sync.tip_track import pivot_tip


@dataclass(frozen=True)
class TipModel:
    """The indenter's cluster in its body frame and the tip in it: a frame's cluster pose
    carries the tip into the lab."""

    cluster_body: np.ndarray   # (M, 3) m
    tip_body: np.ndarray       # (3,) m
    source: str                # the pivot recording or the synced file it came from

    def tips(self, cluster: np.ndarray, params: SyncParams) -> np.ndarray:
        """The tip (T, 3) in the lab frame for cluster markers (T, M, 3); NaN where the pose
        is missing or poor (as sync)."""
        pose = fit_rigid(self.cluster_body, cluster, max_rms=params.max_fit_rms_m,
                         robust_scale=params.robust_scale_m)
        tip = pose.apply(self.tip_body)
        tip[pose.poor | ~pose.valid] = np.nan
        return tip


def tip_model(cfg: SessionConfig, layout: LiveLayout, calibration: Path | None,
              params: SyncParams) -> TipModel:
    """The tip from ``calibration`` (a synced file) or else the session's pivot recording."""
    if calibration is not None:
        got, _ = read_h5(calibration, SYNCED,
                         ["calibration/cluster_body", "calibration/tip_body"])
        return TipModel(np.asarray(got["calibration/cluster_body"], float),
                        np.asarray(got["calibration/tip_body"], float), str(calibration))
    if cfg.pivot_file is None:
        raise BadInput(cfg.folder / "session.toml", "no [pivot] recording and no "
                                                    "--calibration X.h5: the tip offset of "
                                                    "the indenter is unknown")
    pivot = read_mocap(cfg.pivot_file)
    raw = RawSession(name=cfg.name, markers=pivot, force=None,  # type: ignore[arg-type]
                     phantom_markers=list(cfg.mocap.phantom_markers),
                     indenter_markers=list(cfg.mocap.indenter_markers), pivot=pivot)
    body, result = pivot_tip(raw, params)
    return TipModel(body, result.tip_body, str(cfg.pivot_file))


def force_tare(values: np.ndarray, rate_hz: float, source: str) -> Tare:
    """The force's bias from its unloaded start (the force channels' first
    :data:`calib.force_tare.TARE_S` seconds at most, as the session's force stores them: gauge
    volts or a wrench); bad input where the force does not start unloaded."""
    return unloaded_start(values, rate_hz, source)


def wrench(values: np.ndarray, tare: Tare, layout: LiveLayout) -> np.ndarray:
    """The tared wrench (T, 6) in N and N m: gauge volts through the .cal's matrix, or a
    wrench less its bias (as sync calibrates)."""
    matrix = None if layout.calibration is None else layout.calibration.matrix
    return apply_calibration(values, tare.bias, matrix)

"""The twin's force sensor: an ATI Nano17 SI-12-0.12 read as six gauge voltages.

The calibration matrix has the structure of a real Nano17's (``UserAxis`` rows, forces from
gauge pairs 1/3/5 and 4/6, torques from all), scaled to the SI-12-0.12 range (Fx, Fy 12 N;
Fz 17 N; torques 120 N-mm) and perturbed per sensor. The logger sees
``volts = C^-1 @ wrench + bias + noise``, quantised: one count on a gauge moves a force axis by
at most 1/320 N (the SI-12-0.12 resolution). The bias is non-zero and creeps slowly.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from core.series import AtiCalibration

# A real Nano17's UserAxis rows (N and N-mm per volt; SI-50-0.5, FT14048): the gauge pattern
_PATTERN = np.array([
    [-0.00280, -0.06682, 0.31523, -6.83852, -0.23752, 6.63100],
    [-0.16194, 7.91594, 0.23705, -4.07803, 0.10330, -3.73191],
    [7.63129, 0.07876, 7.83947, 0.15734, 7.29931, -0.03120],
    [-1.07922, 48.31227, 44.14521, -24.06649, -41.35823, -22.33469],
    [-48.52430, 0.29188, 23.79766, 42.04846, 24.75501, -40.84329],
    [-0.43239, 28.95078, -1.34298, 27.42373, -1.01262, 28.03461],
])
_PATTERN_RANGE = np.array([50.0, 50.0, 70.0, 500.0, 500.0, 500.0])
RATED = np.array([12.0, 12.0, 17.0, 120.0, 120.0, 120.0])      # SI-12-0.12: N and N-mm
RESOLUTION_N = 1.0 / 320.0
FILE_TO_SI = np.array([1.0, 1.0, 1.0, 1e-3, 1e-3, 1e-3])       # N, N-mm -> N, N*m
ADC_RANGE_V = 10.0


@dataclass
class Nano17:
    """One sensor and its logger channel: matrix in file units (N, N-mm per V), bias, noise."""

    serial: str
    matrix: np.ndarray         # (6, 6) as written in the .cal (5 decimals)
    bias: np.ndarray           # (6,) V at logger time 0
    bias_drift: np.ndarray     # (6,) V/s
    quantum: float             # V per count
    noise: float               # V, white noise standard deviation per gauge

    @property
    def calibration(self) -> AtiCalibration:
        """The calibration as :mod:`ingest.ati_cal` reads it back (SI units)."""
        return AtiCalibration(
            source="phantom twin", serial=self.serial, body_style="Nano17",
            calibration="SI-12-0.12", matrix=self.matrix * FILE_TO_SI[:, None],
            max_load=RATED * FILE_TO_SI, force_units="N", torque_units="N-mm",
            meta={"calibration": {"CalDate": "3/15/2021", "OutputMode": "Ground Referenced "
                                  "Differential", "OutputRange": "20", "HWTempComp": "True",
                                  "GainMultiplier": "1", "OutputBipolar": "True"},
                  "basic_transform": {"Dx": "0", "Dy": "0", "Dz": "0", "Rx": "0", "Ry": "0",
                                      "Rz": "0"}},
        )

    def volts(self, rng: np.random.Generator, force: np.ndarray, torque: np.ndarray,
              time_s: np.ndarray) -> np.ndarray:
        """Logged gauge voltages (T, 6) for a wrench in SI (sensor frame) at logger times."""
        wrench = np.concatenate([force, torque * 1e3], axis=1)          # N, N-mm
        over = np.abs(wrench) > RATED
        if over.any():
            t, axis = np.argwhere(over)[0]
            raise RuntimeError(f"twin load beyond the Nano17's rated range on axis {axis} at "
                               f"logger time {time_s[t]:.3f} s")
        v = np.linalg.solve(self.matrix, wrench.T).T
        v += self.bias + np.outer(time_s, self.bias_drift)
        v += rng.normal(0.0, self.noise, v.shape)
        v = np.round(v / self.quantum) * self.quantum
        if np.abs(v).max() >= ADC_RANGE_V:
            raise RuntimeError("twin gauge voltage beyond the logger's +-10 V input")
        return v

    def wrench(self, volts: np.ndarray, time_s: np.ndarray) -> np.ndarray:
        """The inverse of :meth:`volts` with the true bias: (T, 6) Fx..Tz in N and N*m.

        ``calibration.matrix @ (volts - bias(t))``, the bias creeping linearly with the logger
        time ``time_s``; what is left is the logger's noise and quantisation.
        """
        bias = self.bias + np.outer(time_s, self.bias_drift)
        return (np.asarray(volts) - bias) @ self.calibration.matrix.T


def make_nano17(rng: np.random.Generator, serial: str) -> Nano17:
    """A plausible SI-12-0.12 sensor: the pattern scaled to its range, perturbed a few %."""
    scale = (RATED / _PATTERN_RANGE)[:, None]
    matrix = _PATTERN * scale * (1.0 + rng.normal(0.0, 0.03, (6, 6)))
    matrix = np.round(matrix, 5)
    quantum = RESOLUTION_N / float(np.abs(matrix[:3]).max())
    bias = rng.uniform(0.05, 0.4, 6) * rng.choice([-1.0, 1.0], 6)
    drift = rng.uniform(-2e-5, 2e-5, 6)
    return Nano17(serial=serial, matrix=matrix, bias=bias, bias_drift=drift, quantum=quantum,
                  noise=0.6 * quantum)

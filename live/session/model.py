"""The model's answer beside the measured markers while a press goes on (``--model RUN``).

A trained run (:class:`train.Predictor`) predicts, from a state of the surface and a press
C = [tip start, tip end], where every point goes and how much the force changes, in the phantom
frame. Live, the state is the surface and tip at the contact's start, and the press's end the
tip now: at each drawing of the scene the predictor answers in region mode (the points near the
tip's path move, the force is the whole surface's), and its answer is held against the markers
measured now (L_d over the phantom markers seen, mm) and the force measured now less the force
at the start (N). The frame is the one the session's rest markers give
(:func:`extract.phantom_frame.to_phantom_frame`, sync's rest plane); the answer goes back to
the lab frame to be drawn. A model trained on other markers than the session's is refused
before the first frame; a press the predictor refuses (a surface or tip far outside what it
learned) is a :class:`ModelRefusal`, and the press goes on without the model's answer.
"""

from __future__ import annotations

import warnings
from dataclasses import dataclass, field
from pathlib import Path

import numpy as np

from core.errors import BadInput
from extract.phantom_frame import apply_transform
from sync.sync import TIP
from train.inference.predictor import DEFAULT_REGION, Predictor


@dataclass
class Reading:
    """The model beside the measurement at one frame of a press."""

    predicted: np.ndarray          # (N, 3) the phantom markers as predicted, lab frame, m
    ld_mm: float                   # mean distance to the markers measured (those seen), mm
    force_error_n: float           # predicted less measured change of force, N
    warnings: list[str] = field(default_factory=list)   # the predictor's envelope warnings


class ModelRefusal(Exception):
    """The predictor refused the press under way; ``str()`` says why, in its words."""


class LiveModel:
    """A trained run, checked against the session's markers, answering press by press."""

    def __init__(self, run: Path, phantom_markers: list[str]) -> None:
        self.predictor = Predictor.load(run)
        want = list(phantom_markers) + [TIP]
        names = self.predictor.point_names
        if names is not None and list(names) != want:
            raise BadInput(run, f"trained on the points {', '.join(names[:4])}, ... "
                                f"({len(names)}), this session's are "
                                f"{', '.join(want[:4])}, ... ({len(want)}): another phantom's "
                                "markers")
        self.to_phantom: np.ndarray | None = None    # lab -> phantom frame, once known
        self._start: tuple[np.ndarray, np.ndarray, float] | None = None

    def start(self, phantom: np.ndarray, tip: np.ndarray, force_n: float) -> None:
        """The state at a contact's start: markers (N, 3) and tip (3,) in the lab frame (a
        marker not seen then keeps no place: the press is not predicted), and the force."""
        self._start = None
        if self.to_phantom is None or not (np.isfinite(phantom).all() and
                                           np.isfinite(tip).all()):
            return
        points = apply_transform(self.to_phantom, np.vstack([phantom, tip]))
        self._start = (points.astype(np.float32), points[-1], force_n)

    def at(self, phantom: np.ndarray, tip: np.ndarray, force_n: float) -> Reading | None:
        """The model's answer for the tip now, beside the markers (N, 3) measured now; None
        without a start state or a tip. A :class:`ModelRefusal` where the predictor refuses
        the press: it is not asked again until the next press starts."""
        if self._start is None or not np.isfinite(tip).all():
            return None
        to_phantom = self.to_phantom
        if to_phantom is None:                 # a start state is taken in the phantom's frame
            raise ValueError("a press's start state without the phantom's frame")
        points, tip_start, force_start = self._start
        tip_now = apply_transform(to_phantom, tip)
        condition = np.concatenate([tip_start, tip_now]).astype(np.float32)
        with warnings.catch_warnings(record=True) as caught:
            warnings.simplefilter("always")
            try:
                deformed, dforce = self.predictor.predict(points, condition,
                                                          region=DEFAULT_REGION)
            except ValueError as e:            # the predictor's refusal of its input
                self._start = None
                raise ModelRefusal(str(e)) from None
        back = np.linalg.inv(to_phantom)
        predicted = apply_transform(back, deformed[:-1].astype(float))
        seen = np.isfinite(phantom).all(axis=1)
        ld = float(np.linalg.norm(predicted[seen] - phantom[seen], axis=1).mean()) * 1e3
        return Reading(predicted, ld, float(dforce) - (force_n - force_start),
                       [str(w.message) for w in caught])

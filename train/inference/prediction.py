"""What :meth:`train.Predictor.predict` answers: one type, whatever the level asked.

``p.predict(points, condition)`` and ``p.predict(points, condition, level=0.9)`` both give a
:class:`Prediction`: the deformed points, the change of force, and with a level how far they
may be off (``sure``). It still unpacks as the pair it used to be
(``deformed, dforce = p.predict(...)``); with a level it used to be a triple
(``deformed, dforce, sure``), which still unpacks but warns (DeprecationWarning): read
``.sure`` instead.
"""

from __future__ import annotations

import warnings
from collections.abc import Iterator
from dataclasses import dataclass
from typing import Any

import numpy as np

from train.intervals.lookup import Interval

TRIPLE = ("a prediction with a level unpacked or indexed as (deformed, dforce, sure) is "
          "deprecated: read .points, .dforce and .sure")


@dataclass(frozen=True, slots=True)
class Prediction:
    """The deformed points (N, 3) float32 m, the change of force N, and with a level the
    :class:`~train.intervals.lookup.Interval` at it (None without one)."""

    points: np.ndarray
    dforce: float
    sure: Interval | None = None

    def __iter__(self) -> Iterator[Any]:
        return iter(self._items())

    def __len__(self) -> int:
        return len(self._items())

    def __getitem__(self, i: int | slice) -> Any:
        return self._items()[i]

    def _items(self) -> tuple:
        """The tuple ``predict`` used to give: (points, dforce), with a level (and a
        DeprecationWarning) (points, dforce, sure)."""
        if self.sure is None:
            return self.points, self.dforce
        warnings.warn(TRIPLE, DeprecationWarning, stacklevel=3)
        return self.points, self.dforce, self.sure

"""A setting's accepted values, stated once: a numeric range (:class:`Bound`) or the members of
an enum (:func:`one_of`).

A command's settings dataclass states its bounds (``BOUNDS``, field name -> :class:`Bound`) and
checks them when it is made (:func:`check_bounds`), so that a caller of the library is refused
as the command line is; the command line's option types read the same bounds and refuse a value
as it is parsed (``pipeline/options.py``), in the same words.
"""

from __future__ import annotations

import math
import numbers
from collections.abc import Mapping
from dataclasses import dataclass, fields, replace
from enum import Enum
from typing import Any, TypeVar

from core.errors import BadInput

E = TypeVar("E", bound=Enum)


@dataclass(frozen=True)
class Bound:
    """A finite number (a whole one with ``whole``) within optional ends, each closed unless
    ``min_open``/``max_open``; ``unit`` is shown with a refused value, ``why`` says what the
    bound protects."""

    min: float | None = None
    max: float | None = None
    min_open: bool = False
    max_open: bool = False
    unit: str = ""
    why: str = ""
    whole: bool = False

    def holds(self, x: float) -> bool:
        """Whether the finite number ``x`` lies within the ends."""
        lo_ok = self.min is None or (x > self.min if self.min_open else x >= self.min)
        hi_ok = self.max is None or (x < self.max if self.max_open else x <= self.max)
        return lo_ok and hi_ok

    def describe(self) -> str:
        """The accepted range in words, e.g. ``in (0, 1]`` or ``> 0``."""
        unit = f" {self.unit}" if self.unit else ""
        if self.min is not None and self.max is not None:
            return (f"in {'(' if self.min_open else '['}{self.min:g}, {self.max:g}"
                    f"{')' if self.max_open else ']'}{unit}")
        if self.min is not None:
            return f"{'>' if self.min_open else '>='} {self.min:g}{unit}"
        if self.max is not None:
            return f"{'<' if self.max_open else '<='} {self.max:g}{unit}"
        return "finite"

    def check(self, name: str, value: Any, shown: str | None = None) -> None:
        """BadInput naming ``name`` unless ``value`` is a number of the right kind within
        the range (``shown``: how the refusal writes the value; default its ``str``)."""
        shown = f"{value}" if shown is None else shown
        kind = numbers.Integral if self.whole else numbers.Real
        if isinstance(value, bool) or not isinstance(value, kind):
            raise BadInput(None, f"{name} {value!r}: not a "
                                 f"{'whole number' if self.whole else 'number'}")
        if not math.isfinite(value):
            raise BadInput(None, f"{name} {shown}: not a finite number (must be "
                                 f"{self.describe()})")
        if not self.holds(float(value)):
            unit = f" {self.unit}" if self.unit else ""
            raise BadInput(None, f"{name} {shown}{unit}: must be {self.describe()}"
                                 + (f" ({self.why})" if self.why else ""))

    def scaled(self, factor: float, unit: str) -> Bound:
        """The same range in another unit (``factor`` of it to one of ours), e.g. an option in
        ms of a setting in s: ``scaled(1e3, "ms")``."""
        return replace(self, min=self.min and self.min * factor,      # None and 0 stay
                       max=self.max and self.max * factor, unit=unit)


def check_bounds(settings: object, bounds: Mapping[str, Bound]) -> None:
    """Refuse (BadInput naming the field) a field of ``settings`` outside its bound; None is
    "not given" and passes, and each number of a tuple is checked."""
    for name, bound in bounds.items():
        value = getattr(settings, name)
        for x in value if isinstance(value, tuple) else (value,):
            if x is not None:
                bound.check(name, x)


def check_ranges(settings: Any, bounds: Mapping[str, Bound]) -> None:
    """Refuse (BadInput naming the field) a field of the dataclass ``settings`` outside its
    bound (:func:`check_bounds`), or a (low, high) field whose ends are the wrong way round: a
    prior's ranges."""
    check_bounds(settings, bounds)
    for f in fields(settings):
        span = getattr(settings, f.name)
        if isinstance(span, tuple) and span[0] > span[1]:
            raise BadInput(None, f"{f.name} ({span[0]:g}, {span[1]:g}): not a range "
                                 "(low, high)")


def one_of(kind: type[E], value: Any, name: str) -> E:
    """``value`` as a member of the enum ``kind`` (a member, or its value as text); anything
    else is BadInput naming ``name`` and the members."""
    try:
        return kind(value)
    except ValueError:
        raise BadInput(None, f"{name} {value!r}: must be one of "
                             f"{', '.join(str(m.value) for m in kind)}") from None

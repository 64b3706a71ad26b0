"""Values as text in the files we write: HDF5 attributes and JSON.

h5py hands back a text attribute as ``bytes`` or ``str`` depending on how it was stored, and
``json`` refuses numpy values and paths; these helpers are the one place that says how such
values become text, and how any value becomes one line of it (:func:`one_line`).
"""

from __future__ import annotations

import json
from typing import Any

import numpy as np


def attr_text(value: object) -> str:
    """An HDF5 attribute (``bytes`` or ``str``, as h5py gives it) as text."""
    return value.decode() if isinstance(value, bytes) else str(value)


def jsonable(value: Any) -> Any:
    """A ``json.dumps`` fallback: numpy arrays and scalars as plain numbers, anything else
    (paths, say) as its text."""
    if isinstance(value, np.ndarray | np.generic):
        return value.tolist()
    return str(value)


def to_json(value: Any, **kwargs: Any) -> str:
    """``json.dumps`` that also takes numpy values and paths (see :func:`jsonable`)."""
    return json.dumps(value, default=jsonable, **kwargs)


def one_line(value: Any, limit: int = 200) -> str:
    """A value as one line of text: dicts as ``key value; ...``, lists space-separated, cut
    at ``limit`` characters."""
    if isinstance(value, dict):
        text = "; ".join(f"{k} {one_line(v, limit)}" for k, v in value.items())
    elif isinstance(value, list | tuple):
        text = " ".join(one_line(v, limit) for v in value)
    else:
        text = value if isinstance(value, str) else json.dumps(value, default=str)
    return text if len(text) <= limit else text[:limit - 3] + "..."


def count(n: int, noun: str, plural: str | None = None) -> str:
    """``n`` and ``noun`` in the number it takes: '1 press', '2 presses', '3 states'."""
    if n == 1:
        return f"{n} {noun}"
    return f"{n} {plural or noun + ('es' if noun.endswith(('s', 'sh', 'ch', 'x')) else 's')}"

"""Values as text in the files we write: HDF5 attributes and JSON.

h5py hands back a text attribute as ``bytes`` or ``str`` depending on how it was stored, and
``json`` refuses numpy values and paths; these two helpers are the one place that says how
such values become text.
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

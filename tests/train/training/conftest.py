"""The dent states shared by the training tests."""

from __future__ import annotations

from pathlib import Path

import pytest
from helpers.cgnn_data import dent_fold


@pytest.fixture(scope="module")
def dent(tmp_path_factory: pytest.TempPathFactory) -> tuple[Path, Path]:
    """The dent states (closed-form truth, ``tests/helpers/cgnn_data.py``) and a 2-fold manifest."""
    return dent_fold(tmp_path_factory.mktemp("dent"))

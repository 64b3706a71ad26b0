"""Shared test set-up: the real lab files in ../shared/real_samples (public exports).

Tests that read them use the ``real_samples`` fixture (module-wide through
``pytestmark = pytest.mark.usefixtures("real_samples")``): without the folder they are skipped
with the reason, instead of failing on a missing file.
"""

from __future__ import annotations

from pathlib import Path

import pytest
from helpers.paths import REAL_SAMPLES  # noqa: E402


@pytest.fixture(scope="session")
def real_samples() -> Path:
    """The real lab exports; skips the test when the shared folder is not beside the repo."""
    if not REAL_SAMPLES.is_dir():
        pytest.skip(f"real lab samples not found at {REAL_SAMPLES} (clone with shared/ beside)")
    return REAL_SAMPLES

"""Where the tests find the repository and the real lab files, wherever a test file sits."""

from __future__ import annotations

from pathlib import Path

ROOT = Path(__file__).resolve().parents[2]               # the repository
REAL_SAMPLES = ROOT.parent / "shared" / "real_samples"   # public lab exports, beside a clone

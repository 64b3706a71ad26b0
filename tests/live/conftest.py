"""Twin sessions whose force QTM samples, as a live session's is: through its analog board, or
from a force plate under the phantom."""

from __future__ import annotations

from pathlib import Path

import pytest

from sim.twin.synth_params import SynthParams
from sim.twin.synth_stage import run_synth


@pytest.fixture(scope="session")
def twin_session(tmp_path_factory: pytest.TempPathFactory) -> Path:
    """Four presses at four places (seed 3), force through the analog board: about 35 s."""
    out = tmp_path_factory.mktemp("live") / "session"
    return run_synth(None, out, SynthParams(seed=3, locations=4, repeats=1,
                                            force_via="analog"))


@pytest.fixture(scope="session")
def plate_session(tmp_path_factory: pytest.TempPathFactory) -> Path:
    """The same four presses (seed 3), the force from a force plate under the phantom."""
    out = tmp_path_factory.mktemp("live_plate") / "session"
    return run_synth(None, out, SynthParams(seed=3, locations=4, repeats=1,
                                            force_via="plate"))

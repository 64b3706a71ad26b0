"""What makes the generic model shipped with the package (``train/generic_model.pt``): the
quick demo's generic pre-training (:func:`pipeline.demo_plan.generic_steps`) on the CPU, and
the record of it the file carries (``scripts/build_generic.py`` runs it; a test checks that the
shipped file's record is today's code's, so a change to the prior or the recipe asks for a
rebuild)."""

from __future__ import annotations

import dataclasses
import os
from pathlib import Path

from pipeline.demo_plan import QUICK, Step, generic_steps
from sim.msm.msm_prior import PRIOR

BUILT_BY = "python scripts/build_generic.py"


def build_steps(work: Path) -> list[Step]:
    """The generic model's steps, in ``work``, on the CPU."""
    return generic_steps(work, QUICK, device="cpu")


def build_record(work: Path, torch_version: str) -> dict:
    """How the shipped file is made: the command, the steps (their paths relative to
    ``work``), the prior's ranges and the torch build."""
    prefix = str(work) + os.sep
    return {"built_by": BUILT_BY,
            "steps": [["pipeline", *(a.replace(prefix, "") for a in step.args)]
                      for step in build_steps(work)],
            "prior": {k: list(v) if isinstance(v, tuple) else v
                      for k, v in dataclasses.asdict(PRIOR).items()},
            "torch": torch_version}

"""What makes the generic model shipped with the package (``train/generic_model.pt``): its
recipe (:data:`train.training.generic_recipe.SHIPPED_RECIPE`) run as the generic steps
(:func:`pipeline.demo_plan.generic_steps`) on the CPU, and the record of it the file carries
(``scripts/build_generic.py`` runs it). :func:`changes` says what today's code would build
otherwise than a file's record: a test holds the shipped file to it, so a change to the prior
or the recipe asks for a rebuild, and a change to the demo's own settings does not."""

from __future__ import annotations

import os
from pathlib import Path
from typing import Any

from pipeline.demo_plan import Step, generic_steps
from sim.msm.msm_prior import PRIOR, prior_record
from train.training.generic_recipe import SHIPPED_RECIPE

BUILT_BY = "python scripts/build_generic.py"
DECIDING = ("built_by", "steps", "prior")   # the record's parts that decide the model made


def build_steps(work: Path) -> list[Step]:
    """The generic model's steps, in ``work``, on the CPU."""
    return generic_steps(work, SHIPPED_RECIPE, device="cpu")


def build_record(work: Path, torch_version: str) -> dict[str, Any]:
    """How the shipped file is made: the command, the steps (their paths relative to
    ``work``), the prior's ranges and the torch build."""
    prefix = str(work) + os.sep
    return {"built_by": BUILT_BY,
            "steps": [["pipeline", *(a.replace(prefix, "") for a in step.args)]
                      for step in build_steps(work)],
            "prior": prior_record(PRIOR),
            "torch": torch_version}


def changes(record: dict[str, Any]) -> list[str]:
    """The parts of ``record`` (a shipped file's provenance) that today's build would make
    otherwise (of :data:`DECIDING`; not the torch build, which changes only the rounding):
    empty when the file is current, else it asks for ``python scripts/build_generic.py``."""
    today = build_record(Path("work"), "")
    return [part for part in DECIDING if record.get(part) != today[part]]

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
from sim.msm.mould_prior import MOULDS, mould_record
from sim.msm.msm_prior import PRIOR, prior_record
from train.generic_model import resolve
from train.training.checkpoint import load_checkpoint
from train.training.generic_recipe import SHIPPED_RECIPE, GenericRecipe

BUILT_BY = "python scripts/build_generic.py"
DECIDING = ("built_by", "steps", "prior", "start")   # the record's parts that decide the model


def build_steps(work: Path, g: GenericRecipe = SHIPPED_RECIPE) -> list[Step]:
    """The steps of the generic model ``g`` (the shipped one, or the one for curved labs), in
    ``work``, on the CPU."""
    return generic_steps(work, g, device="cpu")


def build_record(work: Path, torch_version: str, g: GenericRecipe = SHIPPED_RECIPE
                 ) -> dict[str, Any]:
    """How a shipped file is made: the command, the steps (their paths relative to
    ``work``), the prior's ranges, the weights it starts from (their digest, where it starts
    from a shipped model) and the torch build."""
    prefix = str(work) + os.sep
    record = {"built_by": BUILT_BY + (" --curved" if g.moulds else ""),
              "steps": [["pipeline", *(a.replace(prefix, "") for a in step.args)]
                        for step in build_steps(work, g)],
              "prior": mould_record(MOULDS) if g.moulds else prior_record(PRIOR),
              "torch": torch_version}
    if g.start is not None:
        record["start"] = load_checkpoint(resolve(g.start))["provenance"]["weights_sha256"]
    return record


def changes(record: dict[str, Any], g: GenericRecipe = SHIPPED_RECIPE) -> list[str]:
    """The parts of ``record`` (a shipped file's provenance) that today's build of ``g`` would
    make otherwise (of :data:`DECIDING`; not the torch build, which changes only the
    rounding): empty when the file is current, else it asks for ``python
    scripts/build_generic.py`` (``--curved``)."""
    today = build_record(Path("work"), "", g)
    return [part for part in DECIDING if record.get(part) != today.get(part)]

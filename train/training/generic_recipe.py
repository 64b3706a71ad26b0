"""How the generic model shipped with the package (``train/generic_model.pt``) is made, as one
record: what it learns from (phantoms drawn from the MSM prior, :mod:`sim.msm.msm_prior`) and
how (epochs, step size, batch, the training recipe, the seed).

:data:`SHIPPED_RECIPE` holds the values the shipped file was built with, :data:`CURVED_RECIPE`
those of the model for curved labs (``train/generic_curved_model.pt``), which starts from it.
``scripts/build_generic.py`` builds by it (:mod:`pipeline.generic_build`), and the quick demo's
``--pretraining generic`` makes the same model (:mod:`pipeline.demo_plan`, whose paper-sized
and smoke settings are variants of it). Nothing of the demo's own settings (its fine-tuning,
its training flags) reaches the record, so changing them never asks for a rebuild. A test
holds it to what the shipped file says of itself (tests/train/training/test_generic_recipe.py).
Plain data: the command line reads it without loading torch.
"""

from __future__ import annotations

from dataclasses import dataclass

from train import paper
from train.training.recipes import OURS


@dataclass(frozen=True)
class GenericRecipe:
    """The generic model's making: ``phantoms`` drawn from the prior (``simulate --prior``;
    with ``moulds``, curved moulds' solids), each pressed at ``locations`` places along
    ``directions`` directions, one fold of them, pre-trained ``epochs`` epochs at step size
    ``lr`` in batches of ``batch`` by the training recipe named ``recipe``
    (:mod:`train.training.recipes`), from ``start`` (a checkpoint's ``--init``) or afresh;
    every step with ``seed``, whatever the lab's, so every fold of every lab starts from the
    same model."""

    phantoms: int
    locations: int
    directions: int
    epochs: int
    lr: float
    batch: int = paper.BATCH
    recipe: str = OURS.name
    seed: int = 0
    moulds: bool = False          # the phantoms curved moulds' solids (``--prior --moulds``)
    start: str | None = None      # the ``--init`` it fine-tunes (None: a fresh network)

    def training_flags(self) -> tuple[str, ...]:
        """The ``pipeline train`` flags of the recipe (the network its default)."""
        return ("--recipe", self.recipe)


# The shipped model: 24 phantoms of the prior x 4 places x 2 directions (3,072 states), 120
# epochs at 5e-4: a quarter of the fine-tuning's 2e-3, at which the prior's variety silences
# the second and third graph layers (docs/results.md, "One pre-training for every lab").
SHIPPED_RECIPE = GenericRecipe(phantoms=24, locations=4, directions=2, epochs=120, lr=5e-4)

# The model for curved labs: the shipped model above pre-trained on, again, 32 moulds' solids x
# 4 places x 2 directions (4,096 states), 40 epochs at its step size: what it knew of a flat
# block's dent kept, the cap's own learnt (docs/results.md, "A generic model for curved labs").
CURVED_RECIPE = GenericRecipe(phantoms=32, locations=4, directions=2, epochs=40, lr=5e-4,
                              moulds=True, start="generic")

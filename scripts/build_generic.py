"""Rebuild the generic model shipped with the package (``train/generic_model.pt``).

    python scripts/build_generic.py [--curved] [--out FILE] [--work DIR]

Runs the generic model's recipe (:mod:`train.training.generic_recipe`, as the steps of
:mod:`pipeline.generic_build`: ``simulate --prior``, ``split``, ``train``) on one thread and the
CPU, in ``--work`` (a temporary folder unless given), then writes the slimmed checkpoint
(:func:`train.generic_model.slim`) to ``--out``, whole or not at all. On the same CPU kind and
torch build it writes the same bytes (compare with ``cmp``); it prints the weights' digest,
which the file's provenance records too. About 16 minutes on one core (67 s to simulate the
prior, about 14 min to train: docs/results.md).

``--curved`` builds the model for curved labs (``train/generic_curved_model.pt``) by its recipe
(:data:`train.training.generic_recipe.CURVED_RECIPE`): the shipped model pre-trained on the
solids of moulds drawn from their prior (``simulate --prior --moulds``); about 5 minutes.
"""

from __future__ import annotations

import argparse
import os
import subprocess
import sys
import tempfile
from pathlib import Path

ROOT = Path(__file__).resolve().parent.parent
sys.path.insert(0, str(ROOT))
os.environ.update(OMP_NUM_THREADS="1", MKL_NUM_THREADS="1", OPENBLAS_NUM_THREADS="1")

import torch  # noqa: E402

from pipeline.generic_build import build_record, build_steps  # noqa: E402
from train.generic_model import SHIPPED, SHIPPED_CURVED, slim, to_bytes, weights_sha256  # noqa: E402,E501
from train.training.checkpoint import load_checkpoint  # noqa: E402
from train.training.generic_recipe import CURVED_RECIPE, SHIPPED_RECIPE, GenericRecipe  # noqa: E402,E501


def build(work: Path, g: GenericRecipe) -> dict:
    """Run the steps of the generic model ``g`` in ``work``; the slimmed checkpoint with its
    record."""
    steps = build_steps(work, g)
    for step in steps:
        subprocess.run([sys.executable, "-m", "pipeline", "-q", *step.args, "--no-rrd"],
                       cwd=ROOT, check=True)
    model = slim(load_checkpoint(steps[-1].outputs[0]),
                 build_record(work, str(torch.__version__), g))
    model["provenance"]["weights_sha256"] = weights_sha256(model)
    return model


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--curved", action="store_true",
                    help="the model for curved labs, from the shipped one and the moulds' solids")
    ap.add_argument("--out", type=Path, default=None,
                    help="[default: the package's file, train/generic(_curved)_model.pt]")
    ap.add_argument("--work", type=Path, default=None,
                    help="folder for the prior's data and the run [default: a temporary one]")
    a = ap.parse_args()
    g = CURVED_RECIPE if a.curved else SHIPPED_RECIPE
    a.out = a.out or (SHIPPED_CURVED if a.curved else SHIPPED)
    with tempfile.TemporaryDirectory() as tmp:
        model = build((a.work or Path(tmp)).resolve(), g)
    part = a.out.with_name(a.out.name + ".part")
    part.write_bytes(to_bytes(model))
    part.replace(a.out)
    print(f"{a.out}: {a.out.stat().st_size / 1e6:.2f} MB, weights sha256 "
          f"{model['provenance']['weights_sha256']}")


if __name__ == "__main__":
    main()

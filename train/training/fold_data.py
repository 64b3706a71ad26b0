"""A fold's examples for a training run: loaded and checked against their manifest, refused
when nothing in them moves, and the normaliser with the training envelope fitted on them.

A run needs examples that can teach: a fold without training examples, or without validation
ones unless ``no_val`` says so, is refused, and so are training examples in which no point
moves by :data:`STILL_M` and the force changes by less than :data:`STILL_N` (a model trained
on them learns "nothing moves", silently). The normaliser's statistics and the envelope
(:class:`train.model.normalise.Envelope`) come from the training examples alone.
"""

from __future__ import annotations

from dataclasses import replace
from pathlib import Path

import numpy as np
import torch

from core.errors import BadInput
from train.data import Batch, StateTensors, fold_pairs, load_manifest, load_states, make_batch
from train.model.normalise import Envelope, Normaliser, highest_tip
from train.training.train_params import TrainOptions

# Nothing to learn: no point of any training example moves by STILL_M and the force changes by
# less than STILL_N, both below any lab's noise (markers ~0.1 mm, the force sensor ~10 mN).
STILL_M = 1e-6
STILL_N = 1e-3

def fold_examples(data: Path, splits: Path, opts: TrainOptions
                  ) -> tuple[StateTensors, torch.Tensor, torch.Tensor, str]:
    """The states, the fold's training and validation pairs (E, 2), and the data's sha256
    the manifest names; a fold without training examples, or without validation unless
    ``no_val``, or whose training examples do not move, is refused."""
    doc = load_manifest(splits, data)
    states = load_states(data)
    train = fold_pairs(states, doc, opts.fold, "train", data, opts.train_groups)
    val = fold_pairs(states, doc, opts.fold, "val")
    if len(train) == 0:
        raise BadInput(splits, f"fold {opts.fold} has no training example")
    if len(val) == 0 and not opts.no_val:
        raise BadInput(splits, f"fold {opts.fold} has no validation example, so best.pt "
                               "could only be chosen by the training loss: split with a "
                               "validation share, or give --no-val (best.pt = the last epoch)")
    if opts.no_val:
        val = val[:0]
    check_learnable(states, train, data, opts.fold)
    return states, train, val, doc["data"]["sha256"]


def check_learnable(states: StateTensors, pairs: torch.Tensor, data: Path, fold: int,
                    chunk: int = 256) -> None:
    """Refuse training examples in which nothing moves: no point by ``STILL_M`` and the force
    not by ``STILL_N`` (a model trained on them learns "nothing moves", silently)."""
    moved = changed = 0.0
    for rows in pairs.split(chunk):
        s, e = rows[:, 0], rows[:, 1]
        both = states.valid[s] & states.valid[e]
        d = (states.points[e] - states.points[s]).norm(dim=-1) * both
        moved = max(moved, float(d.max()))
        changed = max(changed, float((states.force[e] - states.force[s]).abs().max()))
    if moved < STILL_M and changed < STILL_N:
        raise BadInput(data, f"nothing to learn: in the {len(pairs)} training examples of "
                             f"fold {fold} no point moves more than {moved * 1e6:.3g} um and "
                             f"the force changes by at most {changed * 1e3:.3g} mN (below "
                             f"{STILL_M * 1e6:g} um and {STILL_N * 1e3:g} mN, any lab's noise)")


def fit_normaliser(states: StateTensors, pairs: torch.Tensor, seed: int, most: int = 2000
                   ) -> Normaliser:
    """Statistics of (at most ``most``, seeded) training examples, with the training envelope
    (:func:`training_envelope`)."""
    rng = np.random.default_rng(seed)
    keep = pairs[np.sort(rng.choice(len(pairs), min(most, len(pairs)), replace=False))]
    b = make_batch(states, keep)
    m = b.mask.numpy()
    norm = Normaliser.fit(b.points.numpy(), m, (b.target - b.points).numpy(), b.dforce.numpy())
    return replace(norm, envelope=training_envelope(states, pairs, b))


def training_envelope(states: StateTensors, pairs: torch.Tensor, sample: Batch) -> Envelope:
    """What the training examples span: press lengths, tip depths and forces of every one
    (the no-motion gate's shortest press must leave each of them whole), the tip's height
    above the surface of ``sample``'s, and the highest point of every start state."""
    s, e = pairs[:, 0], pairs[:, 1]
    cond = torch.cat([states.tip[s], states.tip[e]], dim=1).numpy()
    gap = highest_tip(sample.points.numpy(), sample.mask.numpy(), sample.cond[:, :3].numpy())
    top = float(states.points[s][..., 2][states.valid[s]].max())
    return Envelope.fit(cond, (states.force[e] - states.force[s]).numpy(), gap, top)

"""Examples for the cGNN from a states file and a fold manifest.

The states are held once, as tensors; an example is a pair of state indices. A batch is
gathered from them: input ``points[start]``, target ``points[end]``, condition
``C = [tip[start], tip[end]]``, change of force ``force[end] - force[start]``, and the mask of
points valid at both ends (a lab marker missing at either end is left out of the graph, the
pooling and the loss; its coordinates are zeroed so NaN never enters the network).
"""

from __future__ import annotations

from dataclasses import dataclass
from pathlib import Path

import h5py
import numpy as np
import torch

from core.errors import BadInput
from core.provenance import sha256_file
from data_schema.json_docs import check_fold_examples, validate_folds
from data_schema.states import example_groups, validate_states

SETS = ("single", "multi")


@dataclass
class StateTensors:
    """The states of a file, as tensors on one device."""

    points: torch.Tensor     # (S, N, 3) float32, zero where invalid
    valid: torch.Tensor      # (S, N) bool
    tip: torch.Tensor        # (S, 3)
    force: torch.Tensor      # (S,)
    pairs: dict[str, torch.Tensor]   # set -> (E, 2) long: start, end
    width: torch.Tensor | None = None   # (S,) long: the marker slots each state's phantom
    #                                     uses (MSM drawn from a prior); None: all N - 1
    location: np.ndarray | None = None  # (S,) each state's place id (states/location)

    def to(self, device: str | torch.device) -> StateTensors:
        return StateTensors(self.points.to(device), self.valid.to(device), self.tip.to(device),
                            self.force.to(device), {k: v.to(device) for k, v in
                                                    self.pairs.items()}, self.width,
                            self.location)


@dataclass
class Batch:
    """One batch of examples."""

    points: torch.Tensor     # (B, N, 3) input, m
    target: torch.Tensor     # (B, N, 3) deformed, m
    mask: torch.Tensor       # (B, N) valid at both ends
    cond: torch.Tensor       # (B, 6) tip start, tip end, m
    dforce: torch.Tensor     # (B,) N


def load_states(path: str | Path) -> StateTensors:
    """Read and check a ``phantom.states`` 2.0 file."""
    validate_states(path)
    with h5py.File(path, "r") as f:
        pts = f["states/points"][()]
        valid = f["states/valid"][()]
        pairs = {s: torch.from_numpy(np.stack([f[f"{s}/start"][()], f[f"{s}/end"][()]], 1)
                                     .astype(np.int64)) for s in SETS}
        tip, force = f["states/tip"][()], f["states/force"][()]
        width = f["phantoms/markers"][()][f["states/phantom"][()]] \
            if "states/phantom" in f else None
        location = f["states/location"][()]
    pts = np.where(valid[..., None], pts, 0.0).astype(np.float32)
    return StateTensors(torch.from_numpy(pts), torch.from_numpy(valid), torch.from_numpy(tip),
                        torch.from_numpy(force.astype(np.float32)), pairs,
                        None if width is None else torch.from_numpy(width.astype(np.int64)),
                        location)


def load_manifest(path: str | Path, data: str | Path) -> dict:
    """A fold manifest, refused unless it was made from exactly this data file and its ids
    are the file's (the states file is checked too)."""
    doc = validate_folds(path)
    digest = sha256_file(data)
    if doc["data"]["sha256"] != digest:
        raise BadInput(path, f"was made from {doc['data']['file']} with sha256 "
                             f"{doc['data']['sha256'][:12]}..., but {data} has sha256 "
                             f"{digest[:12]}...: re-run `pipeline split` on it")
    validate_states(data)
    check_fold_examples(path, doc, example_groups(data, doc["group_by"]))
    return doc


def role_examples(doc: dict, fold: int, role: str, data: str | Path | None = None,
                  train_groups: int | None = None) -> dict[str, np.ndarray]:
    """Example ids per set of one role of one fold; with ``train_groups`` n, only the
    training examples of the manifest's nested subset n (their groups read from ``data``)."""
    folds = doc["folds"]
    if not 0 <= fold < len(folds):
        raise BadInput(None, f"--fold {fold} is not one of the manifest's {len(folds)} folds")
    part = folds[fold][role]
    ids = {s: np.asarray(part[s], dtype=np.int64) for s in SETS}
    if role != "train" or train_groups is None:
        return ids
    subsets = folds[fold]["train_subsets"]
    if not 1 <= train_groups <= len(subsets):
        raise BadInput(None, f"--train-groups {train_groups}: fold {fold} has "
                             f"{len(subsets)} training groups")
    if data is None:
        raise ValueError("role_examples: train_groups needs the data file its groups are in")
    groups = example_groups(data, doc["group_by"])
    keep = np.asarray(subsets[train_groups - 1])
    return {s: ids[s][np.isin(groups[s][ids[s]], keep)] for s in SETS}


def example_pairs(states: StateTensors, ids: dict[str, np.ndarray]) -> torch.Tensor:
    """(E, 2) start/end state indices of the given example ids, single then multi."""
    return torch.cat([states.pairs[s][torch.as_tensor(ids[s], dtype=torch.long)] for s in SETS])


def fold_pairs(states: StateTensors, doc: dict, fold: int, role: str,
               data: str | Path | None = None, train_groups: int | None = None) -> torch.Tensor:
    """(E, 2) start/end state indices of one role's examples of one fold
    (:func:`role_examples`, :func:`example_pairs`)."""
    return example_pairs(states, role_examples(doc, fold, role, data, train_groups))


def make_batch(states: StateTensors, pairs: torch.Tensor,
               point_idx: torch.Tensor | None = None, cols: torch.Tensor | None = None
               ) -> Batch:
    """Gather a batch for (B, 2) ``pairs``: of its points the columns ``cols`` (n,) only
    (a prior's phantom without its padding, :mod:`train.training.batches`), and of those
    ``point_idx`` (B, n') only."""
    s, e = pairs[:, 0], pairs[:, 1]
    x, y = states.points[s], states.points[e]
    m = states.valid[s] & states.valid[e]
    if cols is not None:
        cols = cols.to(x.device)
        x, y, m = x[:, cols], y[:, cols], m[:, cols]
    if point_idx is not None:
        x = x.gather(1, point_idx.unsqueeze(-1).expand(-1, -1, 3))
        y = y.gather(1, point_idx.unsqueeze(-1).expand(-1, -1, 3))
        m = m.gather(1, point_idx)
    cond = torch.cat([states.tip[s], states.tip[e]], dim=1)
    return Batch(x, y, m, cond, states.force[e] - states.force[s])

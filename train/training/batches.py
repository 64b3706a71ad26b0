"""Which examples go into each batch, and which of their points.

A lab's states have one marker count: an epoch's batches are its shuffled examples cut into
``batch``-sized runs. MSM data drawn from a prior (``simulate --prior``) holds phantoms of
different marker counts, padded to the largest with the tip last (the padding ``valid`` False).
Batches of mixed counts would need the padding masked in the kNN and cost the largest count's
work on every phantom; instead a batch holds the examples of one marker count and gathers only
its points (:class:`Rows` ``cols``): the phantom's markers and the tip (a marker occluded in a
state stays, masked by ``valid`` as in lab data). The batches of every count are cut from the
one shuffle and then put in a random order, so an epoch still sees every example once, in an
order drawn from its seed.
"""

from __future__ import annotations

from dataclasses import dataclass

import torch


@dataclass(frozen=True)
class Rows:
    """One batch: the examples' rows (into the epoch's pairs) and the point columns to
    gather (None: every point)."""

    rows: torch.Tensor
    cols: torch.Tensor | None = None


def epoch_batches(pairs: torch.Tensor, width: torch.Tensor | None, points: int, batch: int,
                  generator: torch.Generator) -> list[Rows]:
    """An epoch's batches of the (E, 2) example ``pairs``: shuffled by ``generator`` and cut
    into ``batch``-sized runs; with ``width`` ((S,) marker slots each state's phantom uses, of
    ``points`` - 1), each batch of one width, the batches in a random order."""
    perm = torch.randperm(len(pairs), generator=generator)
    if width is None:
        return [Rows(rows) for rows in perm.split(batch)]
    out = [Rows(rows, cols)
           for rows, cols in _by_width(perm, width[pairs[:, 0].cpu()[perm]], points, batch)]
    order = torch.randperm(len(out), generator=generator)
    return [out[i] for i in order]


def fixed_batches(count: int, width: torch.Tensor | None, pairs: torch.Tensor, points: int,
                  batch: int) -> list[Rows]:
    """The ``count`` examples in order, cut into batches (of one width each, where the
    states have widths): for validation and scoring, where order does not matter."""
    rows = torch.arange(count)
    if width is None:
        return [Rows(r) for r in rows.split(batch)]
    return [Rows(r, c) for r, c in _by_width(rows, width[pairs[:count, 0].cpu()], points,
                                             batch)]


def _by_width(rows: torch.Tensor, width: torch.Tensor, points: int, batch: int
              ) -> list[tuple[torch.Tensor, torch.Tensor]]:
    """``rows`` grouped by their width (in the rows' order within each), cut into batches,
    with each width's columns: its marker slots and the tip (the last point)."""
    out = []
    for w in torch.unique(width).tolist():
        cols = torch.cat([torch.arange(w), torch.tensor([points - 1])])
        out += [(r, cols) for r in rows[width == w].split(batch)]
    return out

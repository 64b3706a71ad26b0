"""An epoch's batches: a lab's as a plain shuffle, a prior's phantoms one marker count a batch,
gathered without their padding, which the network would have masked anyway."""

from __future__ import annotations

import torch

from train.data import StateTensors, make_batch
from train.model.cgnn import CGNN
from train.model.config import CGNNConfig
from train.training.batches import epoch_batches, fixed_batches

POINTS = 9                       # 8 marker slots, then the tip


def _states(widths: list[int], per: int = 6) -> StateTensors:
    """Phantoms of the given marker counts, ``per`` states each, padded to 8 slots + tip."""
    g = torch.Generator().manual_seed(3)
    s = len(widths) * per
    points = torch.rand(s, POINTS, 3, generator=g)
    valid = torch.zeros(s, POINTS, dtype=torch.bool)
    width = torch.tensor([w for w in widths for _ in range(per)])
    for i, w in enumerate(width):
        valid[i, :w] = True
        valid[i, -1] = True
    points[~valid] = 0.0
    pairs = torch.stack([torch.arange(0, s, 2), torch.arange(1, s, 2)], 1)
    return StateTensors(points, valid, points[:, -1], torch.rand(s, generator=g),
                        {"single": pairs, "multi": pairs[:0]}, width)


def test_a_lab_epoch_is_the_plain_shuffle() -> None:
    pairs = torch.zeros(70, 2, dtype=torch.long)
    got = epoch_batches(pairs, None, POINTS, 32, torch.Generator().manual_seed(5))
    want = torch.randperm(70, generator=torch.Generator().manual_seed(5)).split(32)
    assert [b.cols for b in got] == [None] * 3
    for b, w in zip(got, want, strict=True):
        assert torch.equal(b.rows, w)


def test_a_priors_epoch_has_one_marker_count_a_batch_and_every_example_once() -> None:
    states = _states([3, 5, 3, 8, 5])
    pairs = states.pairs["single"]
    batches = epoch_batches(pairs, states.width, POINTS, 2, torch.Generator().manual_seed(1))
    seen = torch.cat([b.rows for b in batches])
    assert sorted(seen.tolist()) == list(range(len(pairs)))
    for b in batches:
        widths = states.width[pairs[b.rows, 0]]
        w = int(widths[0])
        assert (widths == w).all()
        assert b.cols.tolist() == [*range(w), POINTS - 1]
    again = epoch_batches(pairs, states.width, POINTS, 2, torch.Generator().manual_seed(1))
    assert all(torch.equal(a.rows, b.rows) for a, b in zip(batches, again, strict=True))
    fixed = fixed_batches(len(pairs), states.width, pairs, POINTS, 2)
    assert sorted(torch.cat([b.rows for b in fixed]).tolist()) == list(range(len(pairs)))


def test_the_gathered_batch_predicts_what_the_padded_one_does() -> None:
    """The network masks the padding: the phantom's points gathered without it get the same
    displacements and change of force."""
    states = _states([4, 4])
    pairs = states.pairs["single"]
    torch.manual_seed(0)
    net = CGNN(CGNNConfig(k=3)).eval()
    cols = torch.tensor([0, 1, 2, 3, POINTS - 1])
    padded, gathered = make_batch(states, pairs), make_batch(states, pairs, cols=cols)
    assert torch.equal(gathered.points, padded.points[:, cols])
    with torch.no_grad():
        d_pad, f_pad = net(padded.points, padded.cond, padded.mask)
        d_gat, f_gat = net(gathered.points, gathered.cond, gathered.mask)
    torch.testing.assert_close(d_gat, d_pad[:, cols], rtol=1e-5, atol=1e-6)
    torch.testing.assert_close(f_gat, f_pad, rtol=1e-5, atol=1e-6)

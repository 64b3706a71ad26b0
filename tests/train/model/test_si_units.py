"""The model's SI face (:mod:`train.model.si_units`) against hand numbers: the no-motion gate,
the one conversion of the network's outputs to metres and newtons, the distances and L_d with
a mask, and the loss (paper and balanced)."""

from __future__ import annotations

import pytest
import torch

from train.data import Batch
from train.model.normalise import Envelope, Normaliser
from train.model.si_units import (
    GATE_SHARE,
    MIN_PRESS,
    BatchPrediction,
    deformed,
    distances,
    loss_sum,
    mean_distance,
    newtons,
    press_gate,
)

# the shortest training press 2 mm: the gate's ramp is GATE_SHARE of it, 0.2 mm
ENVELOPE = Envelope(press_min=2e-3, press_max=6e-3, tip_lowest=-5e-3, gap_max=5e-3,
                    force_min=0.0, force_max=3.0, top=1e-3)
NORM = Normaliser((0.05, 0.05, 0.0), 0.03, disp_scale=0.002, force_scale=0.5, extent=0.08,
                  envelope=ENVELOPE)
BARE = Normaliser((0.05, 0.05, 0.0), 0.03, disp_scale=0.002, force_scale=0.5, extent=0.08)


def _presses(*moves: tuple[float, float, float]) -> torch.Tensor:
    """Conditions (B, 6) in float64: a tip starting at (0.05, 0.05, 0.001) moved by each."""
    start = torch.tensor([0.05, 0.05, 0.001], dtype=torch.float64)
    return torch.stack([torch.cat([start, start + torch.tensor(m, dtype=torch.float64)])
                        for m in moves])


def test_the_ramp_is_a_tenth_of_the_shortest_training_press() -> None:
    """The module's stated share: the gate reaches 1 at 0.1 x 2 mm = 0.2 mm (0.19 mm: 0.95;
    0.21 mm: exactly 1)."""
    assert GATE_SHARE == 0.1
    gate = press_gate(NORM, _presses((0, 0, -2.1e-4), (0, 0, -1.9e-4)))
    assert float(gate[0]) == 1.0
    assert float(gate[1]) == pytest.approx(0.95, rel=1e-12)


def test_the_gate_is_zero_for_a_still_tip_linear_below_the_ramp_and_one_above() -> None:
    """|tip end - tip start| / 0.2 mm, capped at 1: a still tip 0; 0.05, 0.1 and 0.15 mm (down,
    or along (3, 4, 0) x 10 um = 50 um) a quarter, a half, three quarters; 0.2 mm and more 1."""
    gate = press_gate(NORM, _presses((0, 0, 0), (0, 0, -5e-5), (3e-5, 4e-5, 0), (0, 0, -1e-4),
                                     (0, 1.5e-4, 0), (0, 0, -2e-4), (0, 0, -3e-3),
                                     (0.01, 0.0, -0.02)))
    expect = torch.tensor([0.0, 0.25, 0.25, 0.5, 0.75, 1.0, 1.0, 1.0], dtype=torch.float64)
    torch.testing.assert_close(gate, expect, rtol=1e-9, atol=1e-12)
    assert float(gate[0]) == 0.0                        # exactly: no motion, no answer


def test_without_an_envelope_the_gate_is_a_step_at_min_press() -> None:
    """A checkpoint without the training envelope ramps over MIN_PRESS (1 nm) alone: 0 for a
    still tip, 0.5 at half a nanometre, 1 for any press a lab can make."""
    assert MIN_PRESS == 1e-9
    gate = press_gate(BARE, _presses((0, 0, 0), (0, 0, -0.5e-9), (0, 0, -1e-9), (0, 0, -1e-6)))
    torch.testing.assert_close(gate, torch.tensor([0.0, 0.5, 1.0, 1.0], dtype=torch.float64),
                               rtol=1e-6, atol=1e-12)


def test_an_envelope_of_still_presses_only_ramps_over_min_press() -> None:
    """press_min 0 (no training press moved): the ramp is MIN_PRESS, never a division by 0."""
    still = Normaliser((0.0, 0.0, 0.0), 0.03, 0.002, 0.5, 0.08,
                       Envelope(0.0, 0.0, 0.0, 0.0, 0.0, 0.0))
    gate = press_gate(still, _presses((0, 0, 0), (0, 0, -0.25e-9), (0, 0, -1e-3)))
    torch.testing.assert_close(gate, torch.tensor([0.0, 0.25, 1.0], dtype=torch.float64),
                               rtol=1e-6, atol=1e-12)


def test_the_gate_reads_each_example_of_a_batch_and_extra_leading_axes() -> None:
    """Shape (B,) for (B, 6), and (A, B) for (A, B, 6): one value per condition."""
    c = _presses((0, 0, -1e-4), (0, 0, 0))
    assert press_gate(NORM, c).shape == (2,)
    both = press_gate(NORM, torch.stack([c, c.flip(0)]))
    torch.testing.assert_close(both, torch.tensor([[0.5, 0.0], [0.0, 0.5]],
                                                  dtype=torch.float64))


def test_deformed_moves_the_points_by_the_scaled_displacement() -> None:
    """disp_scale 2 mm: a normalised (1, -2, 0.5) moves a point by (2, -4, 1) mm; a gate of 0.5
    on the second example halves its move, the first's gate 1 keeps it whole."""
    points = torch.tensor([[[0.01, 0.02, 0.0]], [[0.03, 0.04, 0.001]]], dtype=torch.float64)
    disp = torch.tensor([[[1.0, -2.0, 0.5]], [[1.0, -2.0, 0.5]]], dtype=torch.float64)
    out = deformed(points, disp, NORM)
    torch.testing.assert_close(out, points + torch.tensor([0.002, -0.004, 0.001],
                                                          dtype=torch.float64))
    gated = deformed(points, disp, NORM, torch.tensor([1.0, 0.5], dtype=torch.float64))
    torch.testing.assert_close(gated[0], points[0] + torch.tensor([0.002, -0.004, 0.001],
                                                                  dtype=torch.float64))
    torch.testing.assert_close(gated[1], points[1] + torch.tensor([0.001, -0.002, 0.0005],
                                                                  dtype=torch.float64))
    zero = deformed(points, disp, NORM, torch.zeros(2, dtype=torch.float64))
    assert torch.equal(zero, points)


def test_newtons_scales_the_force_change() -> None:
    """force_scale 0.5 N: a normalised 3 is 1.5 N, -4 is -2 N; gates 0.25 and 1 make 0.375 N
    and -2 N."""
    df = torch.tensor([3.0, -4.0], dtype=torch.float64)
    torch.testing.assert_close(newtons(df, NORM), torch.tensor([1.5, -2.0],
                                                               dtype=torch.float64))
    torch.testing.assert_close(newtons(df, NORM, torch.tensor([0.25, 1.0], dtype=torch.float64)),
                               torch.tensor([0.375, -2.0], dtype=torch.float64))


def _batch() -> tuple[BatchPrediction, Batch]:
    """Two examples of three points. Example 0: off by (3, 4, 0) mm (5 mm), (0, 0, 2) mm and
    (1, 1, 1) m on a masked point; force 0.5 N too high. Example 1: off by 1 mm on every
    point, all valid; force 2 N too low."""
    target = torch.zeros(2, 3, 3, dtype=torch.float64)
    pred = target.clone()
    pred[0, 0] = torch.tensor([3e-3, 4e-3, 0.0], dtype=torch.float64)
    pred[0, 1] = torch.tensor([0.0, 0.0, 2e-3], dtype=torch.float64)
    pred[0, 2] = torch.tensor([1.0, 1.0, 1.0], dtype=torch.float64)
    pred[1, :, 0] = 1e-3
    mask = torch.tensor([[True, True, False], [True, True, True]])
    b = Batch(target.clone(), target, mask, torch.zeros(2, 6, dtype=torch.float64),
              torch.tensor([1.0, 3.0], dtype=torch.float64))
    return BatchPrediction(pred, torch.tensor([1.5, 1.0], dtype=torch.float64)), b


def test_distances_are_euclidean_and_zero_where_masked() -> None:
    """5 mm, 2 mm and a masked point (0, however far off); 1 mm at every point."""
    p, b = _batch()
    want = torch.tensor([[5e-3, 2e-3, 0.0], [1e-3, 1e-3, 1e-3]], dtype=torch.float64)
    torch.testing.assert_close(distances(p, b), want, rtol=1e-12, atol=1e-15)


def test_mean_distance_averages_over_the_valid_points_only() -> None:
    """L_d of example 0 is (5 + 2) / 2 = 3.5 mm (the masked point neither adds nor counts);
    an example with no valid point is 0, not NaN."""
    p, b = _batch()
    torch.testing.assert_close(mean_distance(p, b),
                               torch.tensor([3.5e-3, 1e-3], dtype=torch.float64))
    b.mask[0] = False
    ld = mean_distance(p, b)
    assert float(ld[0]) == 0.0 and float(ld[1]) == pytest.approx(1e-3)


def test_the_paper_loss_sums_alpha_ld_and_the_squared_force_error() -> None:
    """alpha 88: 88 x 3.5 mm + 0.5^2 = 0.558 and 88 x 1 mm + 2^2 = 4.088, summed: 4.646."""
    p, b = _batch()
    assert float(loss_sum(p, b, 88.0)) == pytest.approx(0.308 + 0.25 + 0.088 + 4.0, rel=1e-12)
    assert float(loss_sum(p, b, 1.0)) == pytest.approx(3.5e-3 + 0.25 + 1e-3 + 4.0, rel=1e-12)


def test_a_force_weight_scales_each_example_s_force_term_only() -> None:
    """Weights (0, 2): example 0's force term (0.25) drops out, example 1's (4) doubles; the
    distance terms (0.308, 0.088) stay; balanced, 2.75 - 1 and 0.5 + 2 x 16."""
    p, b = _batch()
    w = torch.tensor([0.0, 2.0], dtype=torch.float64)
    assert float(loss_sum(p, b, 88.0, None, w)) == pytest.approx(0.308 + 0.088 + 8.0, rel=1e-12)
    assert float(loss_sum(p, b, 88.0, NORM, w)) == pytest.approx(1.75 + 0.5 + 32.0, rel=1e-12)


def test_the_balanced_loss_puts_each_term_in_its_training_scale() -> None:
    """disp_scale 2 mm and force_scale 0.5 N: 3.5 / 2 + (0.5 / 0.5)^2 = 2.75 and
    1 / 2 + (2 / 0.5)^2 = 16.5, summed 19.25; alpha is not read."""
    p, b = _batch()
    assert float(loss_sum(p, b, 88.0, NORM)) == pytest.approx(2.75 + 16.5, rel=1e-12)
    assert float(loss_sum(p, b, 1.0, NORM)) == float(loss_sum(p, b, 88.0, NORM))

"""A states file against the phantom twin's truth: shared by the extract and analog tests."""

from __future__ import annotations

import json
from pathlib import Path

import h5py
import numpy as np

from core.protocol import STEP_N, top_level
from data_schema.states import validate_states
from extract.phantom_frame import apply_transform


def truth_levels(truth: h5py.File, press: int) -> int:
    """The highest level the true contact force of a press reached: what extraction must find.

    Not truth's own ``states/step``: the twin solves states up to floor(presses/fmax / 0.5),
    the *planned* peak, while the true force (``force/magnitude``, tremor included) can pass the
    next level (twin seed 101, press 3: fmax 6.970 N, true peak 7.0007 N, so level 14 was
    reached while truth lists states up to 13; benchmarks/bench_extract.py counts such presses)
    or stay short of the planned one. The true force is what the sensor saw, so it decides."""
    force = truth["force/magnitude"][()][truth["mocap/press"][()] == press]
    return top_level(force.max(), STEP_N)


def check_states_against_truth(states: Path, truth: Path) -> dict[str, int]:
    """Every level each press reached, but for the states extract says it excluded; the
    state's points within the markers' own noise of the true ones; the force at each state on
    its level. Returns the exclusions (also used by tests/ingest/test_analog.py)."""
    validate_states(states)
    with h5py.File(states) as s, h5py.File(truth) as t:
        seq, step = s["states/sequence"][()], s["states/step"][()]
        pts, valid, force = s["states/points"][()], s["states/valid"][()], s["states/force"][()]
        to_phantom = s["sessions/transform"][0]
        t_pts, t_step, t_press = t["states/points"][()], t["states/step"][()], \
            t["states/press"][()]
        excluded = json.loads(s.attrs["excluded"])
        missing = 0
        for press in np.unique(t_press):
            found = list(step[seq == press])
            expected = set(range(truth_levels(t, press) + 1))
            assert len(found) == len(set(found)) and set(found) <= expected, (press, found)
            missing += len(expected - set(found))
        assert missing == sum(excluded.values()), (missing, excluded)
        dist = []
        for i in np.flatnonzero(np.isin(step, t_step)):
            j = np.flatnonzero((t_press == seq[i]) & (t_step == step[i]))
            if j.size:
                true = apply_transform(to_phantom, t_pts[j[0]])
                dist.append(np.linalg.norm(pts[i][valid[i]] - true[valid[i]], axis=1).mean())
        assert np.mean(dist) < 0.15e-3                      # below the markers' own 0.18 mm
        np.testing.assert_allclose(force, 0.5 * step, atol=0.02)
    return excluded

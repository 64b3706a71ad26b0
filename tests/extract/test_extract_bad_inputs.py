"""pipeline extract against damaged copies of the synced file it reads.

The harness, the damage and the clean inputs: ``tests/helpers/bad_input_checks.py``,
``tests/helpers/file_damage.py``, ``tests/helpers/bad_input_fixtures.py``.
"""

from __future__ import annotations

from pathlib import Path

import h5py
from helpers.bad_input_checks import Pair, arrays, cli, fuzz
from helpers.file_damage import REFUSE, VALID, Mutation, del_attr, edit_ds, h5_mutations, set_attr

from data_schema.states import STATES, validate_states
from data_schema.synced import PRESS_ATTRS, SYNCED

pytest_plugins = ["helpers.bad_input_fixtures"]


def synced_mutations(path: Path) -> list[Mutation]:
    """The layout's mutations and faults of meaning of a synced file's first press."""
    with h5py.File(path, "r") as f:
        frames, locations = len(f["presses/000/time_ns"]), len(f["locations/centre"])
        press_attrs = list(f["presses/000"].attrs)
    return h5_mutations(path, SYNCED) + [
        Mutation(f"presses/000 attribute {a} deleted", del_attr("presses/000", a),
                 REFUSE if a in PRESS_ATTRS else VALID) for a in press_attrs
    ] + [
        Mutation("onset_index past the press", set_attr("presses/000", "onset_index",
                                                        frames + 5)),
        Mutation("peak_index negative", set_attr("presses/000", "peak_index", -1)),
        Mutation("location past locations/centre", set_attr("presses/000", "location",
                                                             locations + 2)),
        Mutation("time_ns reversed", edit_ds("presses/000/time_ns", lambda a: a[::-1].copy())),
        Mutation("surface_normal not unit", edit_ds("calibration/surface_normal", lambda a: 2 * a)),
        Mutation("units_force mN", set_attr("", "units_force", "mN")),
        Mutation("calibration attribute clock_method deleted",
                 del_attr("calibration", "clock_method")),
    ]


def test_extract_reads_synced(clean_lab, tmp_path) -> None:
    pair = Pair("extract <- synced HDF5", clean_lab / "synced.h5", lambda c: c / "synced.h5",
                lambda p, c: (cli("extract", p, "--out", c / "out.h5", "--no-rrd"),
                              c / "out.h5"),
                lambda out: arrays(out, STATES), validate_states)
    fuzz(pair, synced_mutations(clean_lab / "synced.h5"), tmp_path)


def test_a_flat_and_a_curved_session_are_not_one_phantom() -> None:
    """check_same_phantom: the same markers and footprint, but one session on a mould."""
    from pathlib import Path

    import numpy as np

    from core.errors import BadInput
    from data_schema.phantom import PhantomLayout
    from extract.extract import check_same_phantom
    from extract.synced_presses import Session
    from sim.twin.twin_shape import dome

    names = [f"P{k:02d}" for k in range(25)] + ["tip"]
    flat = Session(Path("a.h5"), "a", np.eye(4), [], [], names, PhantomLayout())
    mould = dome((0.1, 0.1, 0.032), 0.03, "dome:30").shape
    curved = Session(Path("b.h5"), "b", np.eye(4), [], [], names, PhantomLayout(shape=mould))
    check_same_phantom([curved, curved])
    for pair in ([flat, curved], [curved, flat]):
        try:
            check_same_phantom(pair)
        except BadInput as e:
            assert "shape" in str(e) and "\n" not in str(e)
        else:
            raise AssertionError("a flat and a curved session were taken for one phantom")

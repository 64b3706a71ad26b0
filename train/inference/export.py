"""Export a trained cGNN to ONNX, the format game engines' inference runtimes load.

The exported graph takes SI inputs and gives SI outputs (normalisation inside, from
:mod:`train.inference.si_model`): ``points`` (1, N, 3) metres in the phantom frame with N free,
``condition`` (1, 6) metres; outputs ``deformed`` (1, N, 3) metres and ``dforce`` (1,) newtons.
Every graph reads the condition: its outputs are gated by the press length (no motion, no
change: :func:`train.model.si_units.press_gate`), a noCond model's too.

What the graph carries: the no-motion gate and neighbour selection that does not depend on the
order of the points. What it cannot carry (an ONNX graph cannot refuse an input) is written
into the file's ``metadata_props`` (:func:`guards`), with the training envelope as JSON, so
that a runtime can check inputs as :class:`train.Predictor` does; the calibrated intervals
(``intervals``: the conformal table as JSON, null for a checkpoint from before them, and
``intervals_lookup``: how to look a prediction up in it, :func:`intervals_props`); and
``provenance`` (JSON:
:func:`core.provenance.make_provenance`'s record, schema ``phantom.onnx`` 1.0, written by the
export runner :mod:`train.inference.export_stage`: the command and the sha256 of the checkpoint).
"""

from __future__ import annotations

import json
from collections.abc import Mapping
from pathlib import Path

import onnx

from train.inference.predictor import EXTRAPOLATION_FACTOR, LARGE, UNIT_FACTOR
from train.inference.si_model import SIModel, to_onnx
from train.model.knn import EXTRA
from train.model.normalise import TIP_POINT
from train.model.si_units import GATE_SHARE
from train.training.checkpoint import load_checkpoint, model_from

INTERVALS_LOOKUP = (
    "split conformal, binned (train/intervals/): level index i = ceil(100 level) - 1 "
    "into levels 0.01..0.99; a feature's bin is the count of its edges <= its value (the first "
    f"distance edge, {TIP_POINT * 1e3:g} mm, sets a lab's tip marker apart); a point's "
    "radius (m) is points.width[distance bin][depth bin][height bin][i], distance = the "
    "point's (input) distance from the segment tip start - tip end, depth = |tip end - tip "
    "start|, height = the tip start's z less that of the surface point nearest it in x, y "
    f"(a point within {TIP_POINT * 1e3:g} mm of the tip start left out; 0 where none is left) "
    "(m); the change of force's interval is dforce +- force.width[depth bin][height bin][i] "
    "(N); null widths are unbounded; count = the calibration scores behind each; none holds "
    "beyond the training envelope")


def checkpoint_of(run: str | Path) -> Path:
    """The checkpoint a run names: a run folder's best.pt, or the checkpoint file itself."""
    run = Path(run)
    return run / "best.pt" if run.is_dir() else run


def export_onnx(run: str | Path, out: str | Path, props: Mapping[str, str] | None = None
                ) -> None:
    """Write ``out`` (ONNX) from a run folder or checkpoint, N a dynamic axis, with the
    guards it lacks, the training envelope and ``props`` (the runner's provenance) in its
    metadata."""
    state = load_checkpoint(checkpoint_of(run))
    si = SIModel(*model_from(state))
    names = state["meta"]["data"].get("point_names")      # the points it was trained on
    to_onnx(si, out)
    graph = onnx.load(str(out))
    meta = {**guards(si), "point_names": json.dumps(names),
            **intervals_props(state.get("intervals")), **(props or {})}
    for key, value in meta.items():
        entry = graph.metadata_props.add()
        entry.key, entry.value = key, value
    onnx.save(graph, str(out))


def intervals_props(table: dict | None) -> dict[str, str]:
    """The calibrated intervals as ``metadata_props``: the table (JSON, ``null`` for a
    checkpoint from before them) and how a runtime looks a prediction up in it."""
    return {"intervals": json.dumps(table, allow_nan=False),
            "intervals_lookup": INTERVALS_LOOKUP}


def guards(si: SIModel) -> dict[str, str]:
    """The exported graph's ``metadata_props``: units, what it does and does not check, and
    the training envelope (JSON; ``envelope`` null for a checkpoint that did not keep it)."""
    k, norm = si.model.config.k, si.norm
    return {
        "units": "points, condition and deformed in metres (phantom frame); dforce in newtons",
        "carried": "no motion, no change: outputs times min(1, |tip end - tip start| / "
                   f"({GATE_SHARE:g} x envelope.press_min)); neighbour ties broken by the "
                   "points' coordinates "
                   f"(tie groups up to k + {EXTRA} = {k + EXTRA} candidates wide)",
        "not_checked": f"NaN or inf in gives NaN out; fewer than k + 1 = {k + 1} points are "
                       "not refused; no unit check (train.Predictor refuses points farther "
                       f"than {UNIT_FACTOR:g} x extent from centre) and no envelope check (it "
                       f"flags points beyond {EXTRAPOLATION_FACTOR:g} x extent and presses "
                       "outside the envelope); memory grows as N^2 (the kNN is one N x N "
                       f"matrix: train.Predictor runs torch above {LARGE} points)",
        "training_envelope": json.dumps({"centre": list(norm.centre), "extent": norm.extent,
                                         "envelope": norm.to_dict().get("envelope")}),
    }

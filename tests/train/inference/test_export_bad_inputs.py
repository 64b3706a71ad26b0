"""pipeline export against damaged copies of the checkpoint it reads.

The harness, the damage and the clean inputs: ``tests/helpers/bad_input_checks.py``,
``tests/helpers/file_damage.py``, ``tests/helpers/bad_input_fixtures.py``.
"""

from __future__ import annotations

from pathlib import Path

import onnx
from helpers.bad_input_checks import Pair, cli, fuzz
from helpers.file_damage import checkpoint_mutations

pytest_plugins = ["helpers.bad_input_fixtures"]


def _onnx_model(path: Path) -> bytes:
    """An ONNX file less its provenance (which names the checkpoint it was made from)."""
    model = onnx.load(str(path))
    keep = [p for p in model.metadata_props if p.key != "provenance"]
    del model.metadata_props[:]
    model.metadata_props.extend(keep)
    return model.SerializeToString()


def test_export_reads_checkpoint(clean_dent, tmp_path) -> None:
    pair = Pair("export <- checkpoint", clean_dent / "run" / "best.pt", lambda c: c / "best.pt",
                lambda p, c: (cli("export", p, "--onnx", c / "m.onnx"), c / "m.onnx"),
                _onnx_model, lambda out: out.stat().st_size)
    fuzz(pair, checkpoint_mutations(clean_dent / "run" / "best.pt"), tmp_path)

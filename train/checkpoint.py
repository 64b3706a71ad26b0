"""Checkpoints: one dict of plain types and tensors, written atomically, read with weights_only.

``{"model": state_dict, "optimizer": state_dict, "epoch": int, "best_val": float,
"config": CGNNConfig.to_dict(), "norm": Normaliser.to_dict(), "options": {...},
"data": {"file", "sha256"}, "fold": int}``: everything inference needs travels with the weights,
and nothing needs unpickling, so a checkpoint from elsewhere cannot run code on load.
"""

from __future__ import annotations

from pathlib import Path
from typing import Any

import torch

from core.atomic import atomic_output
from core.errors import BadInput
from train.model import CGNN, CGNNConfig
from train.normalise import Normaliser


def save_checkpoint(path: str | Path, state: dict[str, Any]) -> None:
    """Write ``state`` to ``path`` under a temporary name, then rename it into place."""
    with atomic_output(path) as tmp:
        torch.save(state, tmp)


def load_checkpoint(path: str | Path, device: str | torch.device = "cpu") -> dict[str, Any]:
    """Read a checkpoint safely (``weights_only``); a damaged file is bad input."""
    try:
        return torch.load(path, map_location=device, weights_only=True)
    except FileNotFoundError:
        raise BadInput(path, "no such checkpoint") from None
    except Exception as e:  # noqa: BLE001 - torch raises many kinds for a damaged file
        raise BadInput(path, f"not a readable checkpoint ({type(e).__name__}: {e})") from None


def model_from(state: dict[str, Any], device: str | torch.device = "cpu"
               ) -> tuple[CGNN, Normaliser]:
    """The model (eval mode) and normaliser a checkpoint holds."""
    model = CGNN(CGNNConfig.from_dict(state["config"])).to(device)
    model.load_state_dict(state["model"])
    return model.eval(), Normaliser.from_dict(state["norm"])

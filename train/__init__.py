"""The conditional graph neural network (cGNN): model, data over states and folds, training,
evaluation, and :class:`Predictor` for using a trained model.

``from train import Predictor`` loads torch; ``import train`` alone does not.
"""

from __future__ import annotations

from typing import Any


def __getattr__(name: str) -> Any:
    if name == "Predictor":
        from train.inference.predictor import Predictor

        return Predictor
    raise AttributeError(name)

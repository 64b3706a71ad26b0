"""The predictor's two ways to run the network (:mod:`train.inference.backends`): torch, and
ONNX Runtime on graphs traced from the same SI model. Two independent runtimes must give the
same outputs, entry by entry, for each network (the paper's, noCond, and both kinds of
offsets), on a small scene and on one past ``SMALL`` points (the pooled session); and the
choice of backend is ``auto``'s rule."""

from __future__ import annotations

import numpy as np
import pytest
import torch

from train.inference.backends import SMALL, OnnxBackend, TorchBackend, make_backend
from train.inference.si_model import ENTRIES, SIModel, entries
from train.model.cgnn import CGNN
from train.model.config import CGNNConfig, Offsets
from train.model.normalise import Envelope, Normaliser

pytest.importorskip("onnxruntime")

NORM = Normaliser((0.05, 0.05, 0.0), 0.03, disp_scale=0.002, force_scale=0.5, extent=0.08,
                  envelope=Envelope(1e-3, 5e-3, -4e-3, 8e-3, -1.0, 3.0, 0.5e-3))
NETWORKS = {"paper": {}, "noCond": {"use_condition": False},
            "tip offsets": {"offsets": Offsets.GRAPH},
            "head offsets": {"offsets": Offsets.HEADS, "offset_width": 4}}
K = 5


def _si(network: str) -> SIModel:
    torch.manual_seed(0)
    config = CGNNConfig(edge_widths=((8, 8),) * 3, disp_widths=(16,), force_widths=(8, 8, 8),
                        k=K, **NETWORKS[network])
    return SIModel(CGNN(config).eval(), NORM)


def _inputs(n: int) -> dict[str, np.ndarray]:
    """A scene of ``n`` points on a 0.1 m patch, its K nearest (itself included), a press."""
    rng = np.random.default_rng(n)
    points = np.c_[rng.uniform(0, 0.1, (n, 2)), rng.normal(0, 1e-3, n)].astype(np.float32)
    d = ((points[:, None] - points[None]) ** 2).sum(-1)
    neighbours = np.argsort(d, axis=1, kind="stable")[:, :K].astype(np.int64)
    condition = np.array([[0.05, 0.05, 1e-3, 0.051, 0.05, -2e-3]], np.float32)
    return {"points": points[None], "neighbours": neighbours[None], "condition": condition,
            "surface": points[None]}


def _run_all(backend: TorchBackend | OnnxBackend, si: SIModel, n: int
             ) -> dict[str, list[np.ndarray]]:
    """Every entry the network runs, a known scene's presses on the terms of its new scene."""
    feed = _inputs(n)
    out = {}
    for entry in entries(si):
        out[entry] = backend.run(entry, *(feed[name] for name in ENTRIES[entry].inputs))
        if entry == "new_scene":
            feed = {**feed, "disp_terms": out[entry][0], "force_terms": out[entry][1]}
    return out


@pytest.mark.parametrize("network", list(NETWORKS))
@pytest.mark.parametrize("n", [26, SMALL + 44])
def test_torch_and_onnx_runtime_agree_entry_by_entry(network: str, n: int) -> None:
    si = _si(network)
    torch_out = _run_all(TorchBackend(si, torch.device("cpu")), si, n)
    onnx_out = _run_all(OnnxBackend(si, threads=2), si, n)
    assert torch_out.keys() == onnx_out.keys() == set(entries(si))
    for entry, outputs in torch_out.items():
        assert len(outputs) == len(ENTRIES[entry].outputs)
        for name, a, b in zip(ENTRIES[entry].outputs, outputs, onnx_out[entry], strict=True):
            assert a.shape == b.shape, (entry, name)
            np.testing.assert_allclose(a, b, rtol=1e-4, atol=1e-6, err_msg=f"{entry} {name}")
    moved = torch_out[entries(si)[0]][-2]                  # the deformed points
    assert moved.shape == (1, n, 3) and np.isfinite(moved).all()


def test_auto_is_onnx_runtime_on_the_cpu_and_torch_elsewhere() -> None:
    si = _si("paper")
    assert make_backend(si, torch.device("cpu")).name == "onnx"
    assert make_backend(si, torch.device("cpu"), "torch").name == "torch"
    with pytest.raises(ValueError, match="runs on the CPU"):
        make_backend(si, torch.device("cuda"), "onnx")
    with pytest.raises(ValueError, match="backend must be one of"):
        make_backend(si, torch.device("cpu"), "tensorrt")

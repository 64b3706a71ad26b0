"""How a :class:`train.predictor.Predictor` runs the network: torch, or an ONNX Runtime session.

Both take SI numpy arrays (points (1, N, 3), condition (1, 6), the first layer's graph
(1, N, k)) and give SI answers through :class:`train.si_model.SIModel`, so they agree to
float32 rounding. ONNX Runtime runs the same graph with a fraction of torch's per-operator
overhead: at 26 points that overhead is most of the time (``benchmarks/bench_cgnn.py``).
"""

from __future__ import annotations

import io

import numpy as np
import torch

from train.si_model import SIModel, to_onnx

BACKENDS = ("auto", "torch", "onnx")


class TorchBackend:
    """The SI model in torch, on its device, in inference mode."""

    name = "torch"

    def __init__(self, si: SIModel, device: torch.device) -> None:
        self.si, self.device = si.to(device).eval(), device

    def _tensors(self, *arrays: np.ndarray) -> list[torch.Tensor]:
        return [torch.from_numpy(a).to(self.device) for a in arrays]

    @torch.inference_mode()
    def full(self, points: np.ndarray, condition: np.ndarray, neighbours: np.ndarray
             ) -> tuple[np.ndarray, float]:
        deformed, df = self.si(*self._tensors(points, condition, neighbours))
        return deformed[0].cpu().numpy(), float(df[0])

    @torch.inference_mode()
    def force(self, points: np.ndarray, condition: np.ndarray, neighbours: np.ndarray
              ) -> float:
        return float(self.si.force(*self._tensors(points, condition, neighbours))[0])


class OnnxBackend:
    """Two ONNX Runtime sessions (whole model, force alone) traced from the SI model at load."""

    name = "onnx"

    def __init__(self, si: SIModel, threads: int) -> None:
        import onnxruntime as ort

        opts = ort.SessionOptions()
        opts.intra_op_num_threads, opts.inter_op_num_threads = threads, 1
        self.sessions = []
        for force_only in (False, True):
            buf = io.BytesIO()
            to_onnx(si.cpu(), buf, force_only=force_only, with_neighbours=True)
            self.sessions.append(ort.InferenceSession(buf.getvalue(), opts,
                                                      providers=["CPUExecutionProvider"]))

    @staticmethod
    def _feed(points: np.ndarray, condition: np.ndarray, neighbours: np.ndarray) -> dict:
        return {"points": points, "condition": condition, "neighbours": neighbours}

    def full(self, points: np.ndarray, condition: np.ndarray, neighbours: np.ndarray
             ) -> tuple[np.ndarray, float]:
        deformed, df = self.sessions[0].run(None, self._feed(points, condition, neighbours))
        return deformed[0], float(df[0])

    def force(self, points: np.ndarray, condition: np.ndarray, neighbours: np.ndarray
              ) -> float:
        return float(self.sessions[1].run(None, self._feed(points, condition, neighbours))[0][0])


def make_backend(si: SIModel, device: torch.device, backend: str = "auto"
                 ) -> TorchBackend | OnnxBackend:
    """``auto``: ONNX Runtime on a CPU where it is installed, torch otherwise."""
    if backend not in BACKENDS:
        raise ValueError(f"backend must be one of {BACKENDS}, got {backend!r}")
    if backend == "auto":
        try:
            import onnxruntime  # noqa: F401
        except ImportError:
            backend = "torch"
        else:
            backend = "onnx" if device.type == "cpu" else "torch"
    if backend == "onnx":
        if device.type != "cpu":
            raise ValueError("the onnx backend runs on the CPU: use backend='torch' on "
                             f"{device}")
        return OnnxBackend(si, torch.get_num_threads())
    return TorchBackend(si, device)

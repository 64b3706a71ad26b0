"""How a :class:`train.inference.predictor.Predictor` runs the network: torch, or ONNX Runtime
sessions.

Both run the SI model's entries (:data:`train.inference.si_model.ENTRIES`: the whole network,
the force alone, and for a press-independent model the scene and the press apart) on numpy arrays
with a batch of one, and give numpy arrays, so they agree to float32 rounding. ONNX Runtime runs the
same graph with a fraction of torch's per-operator overhead: at 26 points that overhead is
most of the time (``benchmarks/bench_cgnn.py``).
"""

from __future__ import annotations

import io

import numpy as np
import torch

from train.inference.si_model import ENTRIES, SIModel, entries, to_onnx

BACKENDS = ("auto", "torch", "onnx")


class TorchBackend:
    """The SI model in torch, on its device, in inference mode."""

    name = "torch"

    def __init__(self, si: SIModel, device: torch.device) -> None:
        self.si, self.device = si.to(device).eval(), device

    @torch.inference_mode()
    def run(self, entry: str, *arrays: np.ndarray) -> list[np.ndarray]:
        """The outputs of ``entry`` (named in ``ENTRIES``) on ``arrays``, in its order."""
        out = getattr(self.si, ENTRIES[entry].method)(
            *(torch.from_numpy(a).to(self.device) for a in arrays))
        return [t.cpu().numpy() for t in (out if isinstance(out, tuple) else (out,))]


class OnnxBackend:
    """One ONNX Runtime session per entry the model has, traced from the SI model at load."""

    name = "onnx"

    def __init__(self, si: SIModel, threads: int) -> None:
        import onnxruntime as ort

        self.sessions = {}
        opts = ort.SessionOptions()
        opts.intra_op_num_threads, opts.inter_op_num_threads = threads, 1
        for entry in entries(si):
            buf = io.BytesIO()
            to_onnx(si.cpu(), buf, entry)
            self.sessions[entry] = ort.InferenceSession(buf.getvalue(), opts,
                                                        providers=["CPUExecutionProvider"])
        self.inputs = {e: [i.name for i in s.get_inputs()] for e, s in self.sessions.items()}

    def run(self, entry: str, *arrays: np.ndarray) -> list[np.ndarray]:
        """The outputs of ``entry`` (named in ``ENTRIES``) on ``arrays``, in its order."""
        session = self.sessions[entry]
        given = dict(zip(ENTRIES[entry].inputs, arrays, strict=True))
        # a traced graph has no input its outputs do not read (noCond: no condition)
        return session.run(None, {name: given[name] for name in self.inputs[entry]})


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

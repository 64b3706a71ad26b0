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

from train.inference.si_model import ENTRIES, PER_POINT, SIModel, entries, to_onnx

BACKENDS = ("auto", "torch", "onnx")
SMALL = 256     # points: a call of at most these runs on one intra-op thread (OnnxBackend)


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
    """ONNX Runtime sessions per entry the model has, traced from the SI model at load.

    Intra-op threads are chosen per call, by its size (the most points of its per-point
    inputs, ``PER_POINT``): one thread at or below ``SMALL`` points, ``threads`` above. A
    thread pool's hand-offs cost more than they save on a small scene (measured by
    ``benchmarks/bench_cgnn.py``'s thread table; the figures: benchmarks/README.md). A call
    with no per-point input (the paper's force on a known mesh: one vector) always runs on
    one thread.
    """

    name = "onnx"

    def __init__(self, si: SIModel, threads: int) -> None:
        import onnxruntime as ort

        def session(graph: bytes, n: int) -> ort.InferenceSession:
            opts = ort.SessionOptions()
            opts.intra_op_num_threads, opts.inter_op_num_threads = n, 1
            return ort.InferenceSession(graph, opts, providers=["CPUExecutionProvider"])

        self.threads, self.sessions = threads, {}
        for entry in entries(si):
            buf = io.BytesIO()
            to_onnx(si.cpu(), buf, entry)
            self.sessions[entry] = {n: session(buf.getvalue(), n) for n in {1, threads}}
        # per entry, what a call feeds: each session input's name and its place among the
        # entry's arguments (a traced graph has no input its outputs do not read, noCond: no
        # condition), the places of its per-point arguments (``PER_POINT``: the call's size),
        # and the outputs' names (all of them, in order)
        self.feeds = {e: [(i.name, ENTRIES[e].inputs.index(i.name)) for i in s[1].get_inputs()]
                      for e, s in self.sessions.items()}
        self.sized = {e: [k for k, name in enumerate(ENTRIES[e].inputs) if name in PER_POINT]
                      for e in self.sessions}
        self.outputs = {e: [o.name for o in s[1].get_outputs()]
                        for e, s in self.sessions.items()}

    @property
    def inputs(self) -> dict[str, list[str]]:
        """Each entry's session inputs by name, in the session's order."""
        return {e: [name for name, _ in feed] for e, feed in self.feeds.items()}

    def run(self, entry: str, *arrays: np.ndarray) -> list[np.ndarray]:
        """The outputs of ``entry`` (named in ``ENTRIES``) on ``arrays``, in its order."""
        size = max((arrays[k].shape[1] for k in self.sized[entry]), default=0)
        session = self.sessions[entry][1 if size <= SMALL else self.threads]
        return session.run(self.outputs[entry], {name: arrays[k] for name, k in
                                                 self.feeds[entry]})


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

"""The cGNN's SI face: metres in, metres and newtons out, and the errors measured in them.

The network learns in normalised units (:mod:`train.normalise`); everything that runs or scores
a model goes through this one module, so the conversion is written once: training and
evaluation (:func:`predict`, :func:`distances`, :func:`mean_distance`, :func:`loss_sum`), the
predictor and the ONNX export (:class:`SIModel`, :func:`to_onnx`), and the benchmarks.
``neighbours`` (B, N, k), optional, is the first layer's graph: the kNN of the points, which a
caller that keeps the same mesh from call to call computes once.

Loss (paper, "Loss Function"): ``alpha * L_d + MSE(dF)`` with ``L_d`` the mean Euclidean
distance between predicted and true deformed points, in metres, and the force change in
newtons; alpha = 88 (the paper's weight). The "balanced" loss puts each term in its training
scale instead.
"""

from __future__ import annotations

import io
import warnings
from dataclasses import dataclass
from pathlib import Path

import torch
from torch import nn

from train.data import Batch
from train.head_split import HeadTerms, pressed_heads, scene_terms
from train.model import CGNN
from train.normalise import Normaliser

OPSET = 17
MIN_PRESS = 1e-9      # m: the gate's ramp where the checkpoint has no training envelope
GATE_SHARE = 0.1      # of the shortest training press: the gate's ramp


@dataclass
class Prediction:
    """Model outputs in SI units."""

    deformed: torch.Tensor   # (B, N, 3) m
    dforce: torch.Tensor     # (B,) N


def press_gate(norm: Normaliser, condition: torch.Tensor) -> torch.Tensor:
    """The no-motion gate (B,): ``min(1, |tip end - tip start| / ramp)``, the ramp
    ``GATE_SHARE`` of the shortest training press.

    Every output is multiplied by it, so a tip that does not move moves no point and changes
    no force, by construction (in torch, in the ONNX graph, in every entry), and a press far
    shorter than any learned shrinks linearly to nothing (small strains are linear). It is 1
    on every press of at least a tenth of the shortest learned: training is unchanged, and so
    is a held-out press a little shorter than the training ones (it is flagged by
    :class:`train.Predictor`, not scaled). A checkpoint without the training envelope takes
    ``MIN_PRESS``: a step from 0 to 1."""
    shortest = norm.envelope.press_min if norm.envelope is not None else 0.0
    ramp = max(GATE_SHARE * shortest, MIN_PRESS)
    length = torch.linalg.vector_norm(condition[..., 3:] - condition[..., :3], dim=-1)
    return torch.clamp(length / ramp, max=1.0)


def in_si(model: nn.Module, norm: Normaliser, points: torch.Tensor, condition: torch.Tensor,
          mask: torch.Tensor | None = None, neighbours: torch.Tensor | None = None
          ) -> tuple[torch.Tensor, torch.Tensor]:
    """Deformed points (B, N, 3) m and the change of force (B,) N from points (B, N, 3) m and
    C (B, 6) m: normalise, run ``model`` (a :class:`CGNN`, possibly DDP-wrapped), denormalise,
    gate (:func:`press_gate`)."""
    disp, df = model(norm.points(points), norm.condition(condition), mask, neighbours)
    return in_metres(norm, points, disp, df, condition)


def in_metres(norm: Normaliser, points: torch.Tensor, disp: torch.Tensor | None,
              df: torch.Tensor, condition: torch.Tensor
              ) -> tuple[torch.Tensor | None, torch.Tensor]:
    """The network's normalised outputs as deformed points (B, N, 3) m (None when ``disp``
    is) and the change of force (B,) N, gated by the press (:func:`press_gate`)."""
    gate = press_gate(norm, condition)
    return (None if disp is None else deformed(points, disp, norm, gate),
            newtons(df, norm, gate))


def deformed(points: torch.Tensor, disp: torch.Tensor, norm: Normaliser,
             gate: torch.Tensor | None = None) -> torch.Tensor:
    """The deformed points (B, N, 3) m: ``points`` moved by the network's normalised
    displacement ``disp`` (B, N, 3), scaled by ``norm`` and by ``gate`` (B,) where given."""
    scale = norm.disp_scale if gate is None else gate.view(-1, 1, 1) * norm.disp_scale
    return points + disp * scale


def newtons(df: torch.Tensor, norm: Normaliser, gate: torch.Tensor | None = None
            ) -> torch.Tensor:
    """The change of force (B,) N from the network's normalised one, scaled by ``norm`` and
    by ``gate`` (B,) where given."""
    return df * (norm.force_scale if gate is None else gate * norm.force_scale)


def predict(model: nn.Module, norm: Normaliser, b: Batch) -> Prediction:
    """Deformed points and change of force for a batch."""
    return Prediction(*in_si(model, norm, b.points, b.cond, b.mask))


def distances(p: Prediction, b: Batch) -> torch.Tensor:
    """(B, N) Euclidean distance of each predicted point from the truth (0 where masked)."""
    return torch.linalg.vector_norm(p.deformed - b.target, dim=-1) * b.mask


def mean_distance(p: Prediction, b: Batch) -> torch.Tensor:
    """L_d per example (B,): the mean over its valid points."""
    return distances(p, b).sum(1) / b.mask.sum(1).clamp(min=1)


def loss_sum(p: Prediction, b: Batch, alpha: float, norm: Normaliser | None = None
             ) -> torch.Tensor:
    """Sum over the batch of ``alpha * L_d + (dF error)^2`` (divide by the count for the mean).

    With ``norm`` (the "balanced" loss) each term is in its training scale instead:
    ``L_d / disp_scale + (dF error / force_scale)^2``, so neither swamps the other whatever
    the units and data (on the MSM the paper's weights make the force term ~800x the other).
    """
    if norm is None:
        return (alpha * mean_distance(p, b) + (p.dforce - b.dforce) ** 2).sum()
    return (mean_distance(p, b) / norm.disp_scale
            + ((p.dforce - b.dforce) / norm.force_scale) ** 2).sum()


class SIModel(nn.Module):
    """The network with its normaliser folded in.

    Besides the whole network (``forward``, ``force``), a press-independent model
    (:attr:`CGNN.press_independent`) is also run in two parts: :meth:`scene`, once per surface,
    and :meth:`pressed` / :meth:`pressed_force` per press, from the scene's head terms.
    """

    def __init__(self, model: CGNN, norm: Normaliser) -> None:
        super().__init__()
        self.model, self.norm = model, norm

    def forward(self, points: torch.Tensor, condition: torch.Tensor,
                neighbours: torch.Tensor | None = None) -> tuple[torch.Tensor, torch.Tensor]:
        """Deformed points (B, N, 3) m and the change of force (B,) N."""
        return in_si(self.model, self.norm, points, condition, None, neighbours)

    def force(self, points: torch.Tensor, condition: torch.Tensor,
              neighbours: torch.Tensor | None = None) -> torch.Tensor:
        """The change of force (B,) N alone: the displacement head is not run."""
        n = self.norm
        df = self.model.forward_force(n.points(points), n.condition(condition), None,
                                      neighbours)
        return in_metres(n, points, None, df, condition)[1]

    def scene(self, points: torch.Tensor, neighbours: torch.Tensor
              ) -> tuple[torch.Tensor, torch.Tensor]:
        """A surface's head terms, (B, N, H) and (B, H): all a press-independent model
        computes that does not depend on the press (:mod:`train.head_split`; refused for a
        model the split does not hold for)."""
        terms = scene_terms(self.model, self.model.features(self.norm.points(points), None,
                                                            None, neighbours))
        return terms.disp, terms.force

    def scene_and_press(self, points: torch.Tensor, neighbours: torch.Tensor,
                        condition: torch.Tensor) -> tuple[torch.Tensor, ...]:
        """A new surface's head terms and its first press's answer, in one run:
        (disp terms, force terms, deformed points, change of force)."""
        disp_terms, force_terms = self.scene(points, neighbours)
        return disp_terms, force_terms, *self.pressed(points, disp_terms, force_terms, condition)

    def pressed(self, points: torch.Tensor, disp_terms: torch.Tensor,
                force_terms: torch.Tensor, condition: torch.Tensor,
                surface: torch.Tensor | None = None) -> tuple[torch.Tensor, torch.Tensor]:
        """:meth:`forward` from the scene's head terms (of ``points``, or of a subset of them
        in the same order): deformed points (B, N, 3) m and the change of force (B,) N.
        ``surface``: all the scene's points where ``points`` are a part of them and the
        network has head offsets (its force head pools every point's)."""
        n, offsets = self.norm, self.model.offsets is not None   # only they read the points
        disp, df = pressed_heads(self.model, HeadTerms(disp_terms, force_terms),
                                 n.condition(condition), n.points(points) if offsets else None,
                                 n.points(surface) if offsets and surface is not None else None)
        return in_metres(n, points, disp, df, condition)

    def pressed_force(self, force_terms: torch.Tensor, condition: torch.Tensor,
                      surface: torch.Tensor | None = None) -> torch.Tensor:
        """:meth:`force` from the scene's force terms: the change of force (B,) N
        (``surface``: the scene's points, which a network with head offsets reads)."""
        if self.model.offsets is not None and surface is None:
            raise ValueError("a network with head offsets reads the scene's points per press")
        _, df = pressed_heads(self.model, HeadTerms(None, force_terms),
                              self.norm.condition(condition), None,
                              None if surface is None else self.norm.points(surface))
        return newtons(df, self.norm, press_gate(self.norm, condition))


@dataclass(frozen=True)
class Entry:
    """One way to call :class:`SIModel`: its method, named inputs and outputs. Inputs and
    outputs named in ``PER_POINT`` have N as their axis 1 (dynamic in an exported graph)."""

    method: str
    inputs: tuple[str, ...]
    outputs: tuple[str, ...]


ENTRIES = {
    "export": Entry("forward", ("points", "condition"), ("deformed", "dforce")),
    "full": Entry("forward", ("points", "condition", "neighbours"), ("deformed", "dforce")),
    "force": Entry("force", ("points", "condition", "neighbours"), ("dforce",)),
    "new_scene": Entry("scene_and_press", ("points", "neighbours", "condition"),
                       ("disp_terms", "force_terms", "deformed", "dforce")),
    "pressed": Entry("pressed", ("points", "disp_terms", "force_terms", "condition"),
                     ("deformed", "dforce")),
    "pressed_force": Entry("pressed_force", ("force_terms", "condition"), ("dforce",)),
    # a network with head offsets: in a region its force head reads every point of the scene
    "pressed_region": Entry("pressed", ("points", "disp_terms", "force_terms", "condition",
                                        "surface"), ("deformed", "dforce")),
    "pressed_force_offsets": Entry("pressed_force", ("force_terms", "condition", "surface"),
                                   ("dforce",)),
}
PER_POINT = ("points", "neighbours", "disp_terms", "deformed", "surface")


def entries(si: SIModel) -> tuple[str, ...]:
    """The entries a predictor of ``si`` runs: for a press-independent model a new scene
    (its terms and first answer in one run, so one session runs per call), the press on the
    whole of a known scene, and the press in a region and the force alone
    (:func:`press_entries`); otherwise the whole network and the force alone."""
    if si.model.press_independent:
        return ("new_scene", "pressed", *press_entries(si))
    return ("full", "force")


def press_entries(si: SIModel) -> tuple[str, str]:
    """A press-independent model's entries for a press on part of a known scene and for the
    force alone: a network with head offsets also reads the scene's points in both."""
    if si.model.offsets is None:
        return ("pressed", "pressed_force")
    return ("pressed_region", "pressed_force_offsets")


class Call(nn.Module):
    """An entry of :class:`SIModel` as a module's forward (what an exporter traces)."""

    def __init__(self, si: SIModel, entry: str) -> None:
        super().__init__()
        self.si, self.method = si, ENTRIES[entry].method

    def forward(self, *args: torch.Tensor) -> torch.Tensor | tuple[torch.Tensor, ...]:
        return getattr(self.si, self.method)(*args)


def example_inputs(si: SIModel, entry: str, n: int = 26) -> tuple[torch.Tensor, ...]:
    """Inputs of the right shapes and types for ``entry`` at ``n`` points (for tracing; the
    scene's ``surface`` has more)."""
    points = torch.rand(1, n, 3) * 0.1
    made = {"points": points, "surface": torch.rand(1, n + 3, 3) * 0.1,
            "condition": torch.rand(1, 6) * 0.1,
            "neighbours": torch.cdist(points, points).topk(si.model.config.k,
                                                           largest=False).indices,
            "disp_terms": torch.rand(1, n, si.model.disp_head[0].out_features),
            "force_terms": torch.rand(1, si.model.force_head[0].out_features)}
    return tuple(made[name] for name in ENTRIES[entry].inputs)


def to_onnx(si: SIModel, out: str | Path | io.BytesIO, entry: str = "export",
            example_points: int = 26) -> None:
    """Trace one entry of ``si`` to ONNX (default: the whole network, computing its own
    graph, as ``pipeline export`` writes it), N a dynamic axis."""
    e = ENTRIES[entry]
    axes = {name: {1: "M" if name == "surface" else "N"}      # a region's N, the scene's M
            for name in (*e.inputs, *e.outputs) if name in PER_POINT}
    with torch.no_grad(), warnings.catch_warnings():
        warnings.simplefilter("ignore", DeprecationWarning)     # the TorchScript exporter
        torch.onnx.export(Call(si, entry).eval(), example_inputs(si, entry, example_points),
                          out if isinstance(out, io.BytesIO) else str(out),
                          input_names=list(e.inputs), output_names=list(e.outputs),
                          opset_version=OPSET, dynamic_axes=axes, dynamo=False)

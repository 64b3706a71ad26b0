"""The cGNN with its normaliser folded in, and the ways a predictor or an exporter calls it.

:class:`SIModel` runs the whole network in SI units (:mod:`train.model.si_units`), and a
press-independent network (:attr:`train.model.config.Offsets.press_independent`) also in two
parts: :meth:`SIModel.scene`, once per surface, and :meth:`SIModel.pressed` /
:meth:`SIModel.pressed_force` per press, from the scene's head terms
(:mod:`train.inference.head_split`). :data:`ENTRIES` names each way to call it: what both
backends run and the exporter traces (:func:`to_onnx`).
"""

from __future__ import annotations

import io
import warnings
from dataclasses import dataclass
from pathlib import Path

import torch
from torch import nn

from train.inference.head_split import HeadTerms, pressed_heads, scene_terms
from train.model.cgnn import CGNN
from train.model.normalise import Normaliser
from train.model.si_units import in_metres, in_si, newtons, press_gate

OPSET = 17


class SIModel(nn.Module):
    """The network with its normaliser folded in.

    Besides the whole network (``forward``, ``force``), a press-independent model
    (:attr:`train.model.config.Offsets.press_independent`) is also run in two parts:
    :meth:`scene`, once per surface, and :meth:`pressed` / :meth:`pressed_force` per press,
    from the scene's head terms.
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
        computes that does not depend on the press (:mod:`train.inference.head_split`; refused for a
        model the split does not hold for)."""
        terms = scene_terms(self.model, self.model.features(self.norm.points(points), None,
                                                            None, neighbours))
        if terms.disp is None:              # scene_terms gives it unless told not to
            raise ValueError("no displacement head terms")
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
        n, reads = self.norm, self.model.offsets.in_heads      # only they read the points
        disp, df = pressed_heads(self.model, HeadTerms(disp_terms, force_terms),
                                 n.condition(condition), n.points(points) if reads else None,
                                 n.points(surface) if reads and surface is not None else None)
        if disp is None:                    # the terms hold the displacement head's
            raise ValueError("no displacement from the scene's head terms")
        return in_metres(n, points, disp, df, condition)

    def pressed_force(self, force_terms: torch.Tensor, condition: torch.Tensor,
                      surface: torch.Tensor | None = None) -> torch.Tensor:
        """:meth:`force` from the scene's force terms: the change of force (B,) N
        (``surface``: the scene's points, which a network with head offsets reads)."""
        if self.model.offsets.in_heads and surface is None:
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
    # a network with offsets in its heads reads the scene's points ("surface") per press: its
    # force head pools every point's, its displacement head those of the region's points
    "pressed_surface": Entry("pressed", ("points", "disp_terms", "force_terms", "condition",
                                         "surface"), ("deformed", "dforce")),
    "pressed_force_surface": Entry("pressed_force", ("force_terms", "condition", "surface"),
                                   ("dforce",)),
}
PER_POINT = ("points", "neighbours", "disp_terms", "deformed", "surface")


def entries(si: SIModel) -> tuple[str, ...]:
    """The entries a predictor of ``si`` runs: for a press-independent model a new scene
    (its terms and first answer in one run, so one session runs per call), the press on the
    whole of a known scene, and the press in a region and the force alone
    (:func:`press_entries`); otherwise the whole network and the force alone."""
    if si.model.offsets.press_independent:
        return ("new_scene", "pressed", *press_entries(si))
    return ("full", "force")


def press_entries(si: SIModel) -> tuple[str, str]:
    """A press-independent model's entries for a press on part of a known scene and for the
    force alone: a network with head offsets also reads the scene's points in both."""
    if si.model.offsets.in_heads:
        return ("pressed_surface", "pressed_force_surface")
    return ("pressed", "pressed_force")


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
            "disp_terms": torch.rand(1, n, si.model.disp_head.first.out_features),
            "force_terms": torch.rand(1, si.model.force_head.first.out_features)}
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
                          # the TorchScript exporter (dynamo=False) also writes to a BytesIO,
                          # which torch's annotation (str | PathLike | None; not 2.4's) leaves out
                          out if isinstance(out, io.BytesIO) else str(out),  # type: ignore[arg-type, unused-ignore]
                          input_names=list(e.inputs), output_names=list(e.outputs),
                          opset_version=OPSET, dynamic_axes=axes, dynamo=False)

"""Where each option of each ``pipeline`` command reads its default and its bound: the fields
of the command's settings (Params dataclasses), by the option's name (the rule:
``tests/pipeline/test_cli_defaults.py``). Shared by the tests of the defaults and of the
refusals."""

from __future__ import annotations

import dataclasses
from collections.abc import Iterator, Mapping
from typing import Any, get_type_hints

import click

from core.bounds import Bound
from extract.extract_params import ExtractParams
from ingest.ingest_params import IngestParams
from live.replay.replay_params import ReplayParams
from live.session.live_params import LiveParams
from pipeline import demo_plan
from pipeline.cli import COMMANDS, cli
from pipeline.demo_pool import WORKERS
from sim.msm.fit_msm_params import FitMsmParams
from sim.msm.simulate_params import SimulateParams
from sim.solid.fit_solid_params import FitSolidParams
from sim.twin.synth_params import SynthParams
from split.split_params import SplitParams
from sync.sync_params import SyncParams
from train.evaluation.eval_params import EvalParams
from train.inference.export_params import ExportParams
from train.model.config import CGNNConfig
from train.training.recipes import PAPER
from train.training.train_params import TrainOptions, TrainParams

LAB = demo_plan.Lab
# (default, bound[, enum]) of the options no dataclass holds, by the option's name
Named = Mapping[str, tuple[Any, Bound | None] | tuple[Any, Bound | None, type]]

SETTINGS: dict[str, tuple[type | Named, ...]] = {
    "synth": (SynthParams,),
    "ingest": (IngestParams,),
    "sync": (SyncParams,),
    "extract": (ExtractParams,),
    "split": (SplitParams,),
    "simulate": (SimulateParams,),
    "fit-msm": (FitMsmParams,),
    "fit-solid": (FitSolidParams,),
    "train": (TrainOptions, CGNNConfig, TrainParams, {"recipe_name": (PAPER.name, None)}),
    "eval": (EvalParams,),
    "export": (ExportParams,),
    "live": (LiveParams, {"address": ((LiveParams.host, LiveParams.port), None)}),
    "replay": (ReplayParams,),
    "inspect": (),
    "demo": ({"out": (demo_plan.OUT, None), "seed": (SynthParams.seed, None),
              "device": (TrainParams.device, None),
              "pretraining": (demo_plan.Pretraining.SHIPPED, None, demo_plan.Pretraining),
              "jobs": (None, WORKERS), "markers": (LAB.markers, None),
              "marker_pitch": (LAB.marker_pitch_mm, SynthParams.BOUNDS["marker_pitch_mm"]),
              "size": (LAB.size_mm, None),
              "mocap_rate": (LAB.mocap_rate_hz, SynthParams.BOUNDS["rate_hz"])},),
}
UNITS = ("s", "m", "n", "hz", "deg", "mm", "ppm")      # a unit a field's name may end with
UNIT_FACTOR = 1e3                                      # ms of s, mm of m


@dataclasses.dataclass(frozen=True)
class Setting:
    """Where an option's default, bound and type are read: a field, or a named value."""

    default: Any
    bound: Bound | None
    kind: Any = None             # the field's annotated type


def settings_of(holder: type | Named) -> dict[str, Setting]:
    if isinstance(holder, Mapping):
        return {name: Setting(*pair) for name, pair in holder.items()}
    hints = get_type_hints(holder)
    bounds = getattr(holder, "BOUNDS", {})
    out = {}
    for f in dataclasses.fields(holder):
        default = f.default if f.default is not dataclasses.MISSING else (
            f.default_factory() if f.default_factory is not dataclasses.MISSING else None)
        out[f.name] = Setting(default, bounds.get(f.name), hints[f.name])
    return out


def field_names(option: str) -> Iterator[tuple[str, float]]:
    """The fields an option may be read from, with the factor of the option's unit to the
    field's."""
    yield option, 1.0
    for unit in UNITS:
        yield f"{option}_{unit}", 1.0
    for ours, theirs in (("_ms", ("_s",)), ("_mm", ("_m", ""))):
        if option.endswith(ours):
            for end in theirs:
                yield option[: -len(ours)] + end, UNIT_FACTOR


def lookup(command: str, option: str) -> tuple[Setting, float] | None:
    found = [settings_of(h) for h in SETTINGS[command]]
    for name, factor in field_names(option):
        for settings in found:
            if name in settings:
                return settings[name], factor
    return None


def commands() -> list[tuple[str, click.Command]]:
    ctx = click.Context(cli)
    return [(name, cli.get_command(ctx, name)) for name in COMMANDS]


def options() -> list[tuple[str, click.Option]]:
    return [(name, p) for name, cmd in commands() for p in cmd.params
            if isinstance(p, click.Option)]


OPTIONS = options()
IDS = [f"{c} --{p.name}" for c, p in OPTIONS]



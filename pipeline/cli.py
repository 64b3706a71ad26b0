"""The `pipeline` command: a thin click layer over the stage functions.

Commands are imported only when run, so `pipeline --help` stays fast and a stage's heavy
dependencies (torch, ezc3d) load only for the stage that needs them. Each stage module exposes
one click command; register it in ``COMMANDS``.
"""

from __future__ import annotations

import importlib
import importlib.util

import click

from core.errors import BadInput
from core.progress import set_quiet

# command name -> "module:attribute" of its click command, in the order of the stages.
COMMANDS: dict[str, str] = {
    "synth": "pipeline.synth_cmd:synth",
    "ingest": "pipeline.ingest_cmd:ingest",
    "sync": "pipeline.sync_cmd:sync",
    "extract": "pipeline.extract_cmd:extract",
    "split": "pipeline.split_cmd:split",
    "simulate": "pipeline.simulate_cmd:simulate",
    "fit-msm": "pipeline.fit_msm_cmd:fit_msm",
    "fit-solid": "pipeline.fit_solid_cmd:fit_solid",
    "train": "pipeline.train_cmd:train",
    "eval": "pipeline.eval_cmd:eval_",
    "export": "pipeline.export_cmd:export",
    "live": "pipeline.live_cmd:live",
    "replay": "pipeline.replay_cmd:replay",
    "inspect": "pipeline.inspect_cmd:inspect",
    "demo": "pipeline.demo_cmd:demo",
}


class PipelineGroup(click.Group):
    """Lazily loaded commands; bad input becomes one line on stderr and exit status 2."""

    def list_commands(self, ctx: click.Context) -> list[str]:
        return [name for name in COMMANDS if self._available(name)]

    def get_command(self, ctx: click.Context, name: str) -> click.Command | None:
        if name not in COMMANDS:
            return None
        module, _, attr = COMMANDS[name].partition(":")
        try:
            return getattr(importlib.import_module(module), attr)
        except ModuleNotFoundError as e:
            if e.name == module:
                return None
            raise

    def _available(self, name: str) -> bool:
        module = COMMANDS[name].partition(":")[0]
        return importlib.util.find_spec(module) is not None

    def invoke(self, ctx: click.Context):  # noqa: ANN201 - click's signature
        try:
            return super().invoke(ctx)
        except BadInput as e:
            click.echo(f"error: {e.line()}", err=True)
            ctx.exit(2)


@click.group(cls=PipelineGroup, context_settings={"help_option_names": ["-h", "--help"]})
@click.option("--quiet", "-q", is_flag=True, help="No progress bars.")
@click.version_option(package_name="phantom-pipeline")
def cli(quiet: bool) -> None:
    """Soft-tissue phantom experiments to a trained, evaluated cGNN.

    \b
    A lab session: synth (or your lab's files) -> ingest -> sync -> extract -> split
      -> train -> eval -> export.
    The MSM the network is pre-trained on: simulate, fit-msm; the solid model of the
      phantom with its interior: fit-solid.
    Sessions as they happen: live (from QTM's real-time stream), replay (a recorded
      session served as QTM's real-time server).
    Any file: inspect. Every stage on a synthetic session: demo.

    Each command's --help says what it reads and writes.
    """
    set_quiet(quiet)


def main() -> None:
    """Console-script entry point."""
    cli(prog_name="pipeline")

"""A twin session taken through the offline stages, for the tests of one force route."""

from __future__ import annotations

from pathlib import Path

from click.testing import CliRunner

from pipeline.cli import cli


def staged_twin(folder: Path, *synth_options: str) -> Path:
    """``pipeline synth`` with ``synth_options`` (seed 3, 2 locations x 2 repeats), then
    ingest, sync and extract, into ``folder`` (s/, s.mcap, synced.h5, states.h5)."""
    for args in (("synth", folder / "s", "--seed", "3", "--locations", "2", "--repeats", "2",
                  *synth_options, "--no-rrd"),
                 ("ingest", folder / "s", "--out", folder / "s.mcap", "--no-rrd"),
                 ("sync", folder / "s.mcap", "--out", folder / "synced.h5", "--no-rrd"),
                 ("extract", folder / "synced.h5", "--out", folder / "states.h5", "--no-rrd")):
        res = CliRunner().invoke(cli, ["-q", *map(str, args)])
        assert res.exit_code == 0, res.output + res.stderr
    return folder

"""Every command refuses a value out of its option's bounds or choices in one line naming the
option, with exit status 2 and nothing written, before its stage is reached; and the command's
settings dataclass refuses the same value as it is made, so that a caller of the library is
refused as the command line is.

The values refused are derived from each option's own bound (just past each end, and NaN for a
float) and choices, so every bounded option of every command is covered; which settings field
each option sets is ``tests/helpers/cli_settings.py``'s rule.
"""

from __future__ import annotations

import dataclasses
from pathlib import Path

import click
import pytest
from click.testing import CliRunner
from helpers.cli_settings import OPTIONS, SETTINGS, field_names

from core.errors import BadInput
from pipeline.cli import cli
from pipeline.options import BoundedInt, FiniteFloat, OneOf


def _outside(option: click.Option) -> list[str]:
    """Values just beyond each end of the option's range (and NaN for a float)."""
    b = option.type.bound
    step = 1 if b.whole else 0.5
    out = []
    if b.min is not None:
        out.append(b.min if b.min_open else b.min - step)
    if b.max is not None:
        out.append(b.max if b.max_open else b.max + step)
    return [repr(v) for v in out] + ([] if b.whole else ["nan"])


CASES = [(command, option, value) for command, option in OPTIONS
         if isinstance(option.type, FiniteFloat | BoundedInt) for value in _outside(option)] + \
        [(command, option, "bogus") for command, option in OPTIONS
         if isinstance(option.type, OneOf)]
IDS = [f"{c} {max(o.opts, key=len)} {v}" for c, o, v in CASES]


def _flag(option: click.Option) -> str:
    return max(option.opts, key=len)


def _refused(args: list[str], tmp_path: Path, monkeypatch: pytest.MonkeyPatch) -> str:
    """The one line ``pipeline ARGS`` says on stderr, checked: exit 2, nothing written."""
    monkeypatch.chdir(tmp_path)
    res = CliRunner().invoke(cli, ["-q", *args])
    assert res.exit_code == 2, (args, res.output, res.exception)
    lines = res.stderr.strip().splitlines()
    assert len(lines) == 1 and lines[0].startswith("error: "), res.stderr
    assert not any(tmp_path.iterdir()), args
    return lines[0]


@pytest.mark.parametrize(("command", "option", "value"), CASES, ids=IDS)
def test_an_option_out_of_its_bounds_or_choices_is_one_line(tmp_path, monkeypatch, command,
                                                            option, value) -> None:
    line = _refused([command, _flag(option), *[value] * option.nargs], tmp_path, monkeypatch)
    assert line.startswith(f"error: {_flag(option)} "), line


@pytest.mark.parametrize(("command", "option", "value"), CASES, ids=IDS)
def test_its_settings_refuse_the_same_value(command, option, value) -> None:
    """The dataclass that holds the option's field refuses the value (in the field's unit)."""
    held = [(h, n, f) for n, f in field_names(option.name) for h in SETTINGS[command]
            if dataclasses.is_dataclass(h) and n in _fields(h)]
    if not held:
        pytest.skip("an option of the command alone (no settings field)")
    holder, name, factor = held[0]
    typed = value if isinstance(option.type, OneOf) else \
        (int(value) if option.type.bound.whole else float(value) / factor)
    if option.nargs == 2:
        typed = (typed, typed)
    with pytest.raises(BadInput, match=f"{name}|{name.replace('_', '-')}"):
        holder(**{name: typed})


def _fields(holder: type) -> set[str]:
    return {f.name for f in dataclasses.fields(holder)}


# --- refusals that are no single option's --------------------------------------------------

@pytest.fixture
def inputs(tmp_path: Path) -> Path:
    """Files the options name (never read: each case is refused first)."""
    d = tmp_path / "in"
    d.mkdir()
    for name in ("states.h5", "splits.json", "a.h5", "b.h5"):
        (d / name).write_bytes(b"never read")
    return d


@pytest.mark.parametrize(("args", "words"), [
    (["train", "--ema", "0.9", "--no-ema"], "--ema and --no-ema"),
    (["train", "--no-val", "--patience", "3"], "patience counts epochs"),
    (["train", "--recipe", "ours", "--no-cond"], "add --offsets none"),
    (["simulate", "--merge", "--shard", "0/2", "--out", "x.h5"], "--merge and --shard"),
    (["simulate", "{in}/a.h5", "{in}/b.h5", "--out", "x.h5"], "SHARDS are only read with"),
    (["simulate", "--prior", "2", "--k-between", "50", "--out", "x.h5"], "--k-between"),
    (["synth", "out", "--force-via", "analog", "--mocap-rate", "300"], "does not divide"),
    (["synth", "out", "--force-via", "plate", "--offset", "1"], "the logger's clock"),
])
def test_contradictions_are_one_line(inputs, tmp_path, monkeypatch, args, words) -> None:
    if args[0] == "train":
        args = [*args, "--data", str(inputs / "states.h5"), "--splits",
                str(inputs / "splits.json"), "--out", "run"]
    args = [a.replace("{in}", str(inputs)) for a in args]
    work = tmp_path / "work"
    work.mkdir()
    assert words in _refused(args, work, monkeypatch)

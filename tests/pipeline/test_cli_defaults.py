"""Every option of every ``pipeline`` command takes its default, its choices and its bounds from
the code that takes the setting, so that each is stated once.

The rule, for each option of each command (click's command objects, as ``pipeline`` loads them):

- its default is None or False (nothing given, a switch off), or the default of the field of the
  same name in one of the command's settings (``SETTINGS`` in ``tests/helpers/cli_settings.py``:
  its Params dataclasses; where a command has an option that no dataclass holds, the name it is
  read from). An option in ms or
  mm of a field in s or m (``max_gap_ms`` of ``max_gap_s``, ``spacing_mm`` of ``spacing``)
  has 1000 times the field's default; a field may carry its unit in its name
  (``marker_pitch`` of ``marker_pitch_mm``);
- a bounded option (a number within a range) has its field's bound (the dataclass's
  ``BOUNDS``), scaled the same way;
- a choice is one of fixed names (:class:`pipeline.options.OneOf`, refused in one line), an
  enum's values where its field is that enum;
- and in the source of ``pipeline/*_cmd.py`` no option's ``default=`` holds a literal (but
  None, True, False and the 1000 of a unit), no ``type=`` a number (a bound) or a choice spelled
  out, and no module-level name a number: they are read from the code that branches on them.
"""

from __future__ import annotations

import ast
import enum
import math
import re
from collections.abc import Iterator
from pathlib import Path
from typing import Any

import click
import pytest
from helpers.cli_settings import IDS, OPTIONS, SETTINGS, UNIT_FACTOR, lookup

from pipeline.cli import COMMANDS, cli
from pipeline.options import BoundedInt, FiniteFloat, OneOf

PIPELINE = Path(__file__).resolve().parents[2] / "pipeline"


def test_every_command_has_its_settings_listed() -> None:
    assert set(SETTINGS) == set(COMMANDS)


def _unset(value: Any) -> bool:
    return value is None or value is False or value == () or \
        type(value).__name__ == "Sentinel"


def _scaled(value: Any, factor: float) -> Any:
    if factor == 1.0 or value is None:
        return value
    return tuple(v * factor for v in value) if isinstance(value, tuple) else value * factor


@pytest.mark.parametrize(("command", "option"), OPTIONS, ids=IDS)
def test_a_default_is_its_settings_field(command: str, option: click.Option) -> None:
    if _unset(option.default) or option.required:
        return
    found = lookup(command, option.name)
    assert found is not None, f"{command} --{option.name}: no field of its settings holds " \
                              f"its default {option.default!r}"
    setting, factor = found
    assert option.default == _scaled(setting.default, factor), (command, option.name)


@pytest.mark.parametrize(("command", "option"), OPTIONS, ids=IDS)
def test_a_bound_is_its_settings_bound(command: str, option: click.Option) -> None:
    if not isinstance(option.type, FiniteFloat | BoundedInt):
        return
    found = lookup(command, option.name)
    assert found is not None and found[0].bound is not None, \
        f"{command} --{option.name}: a range that no setting states"
    bound, factor = found[0].bound, found[1]
    if factor != 1.0:
        bound = bound.scaled(factor, option.type.bound.unit)
    got = option.type.bound
    assert (got.min, got.max, got.whole) == (bound.min, bound.max, bound.whole), \
        (command, option.name)
    if not bound.whole:
        assert (got.min_open, got.max_open) == (bound.min_open, bound.max_open)


@pytest.mark.parametrize(("command", "option"), OPTIONS, ids=IDS)
def test_a_choice_is_one_of_the_codes_names(command: str, option: click.Option) -> None:
    if not isinstance(option.type, click.Choice):
        return
    assert isinstance(option.type, OneOf), f"{command} --{option.name}: refused in one line"
    found = lookup(command, option.name)
    kind = found[0].kind if found else None
    if isinstance(kind, type) and issubclass(kind, enum.Enum):
        assert option.type.kind is kind
        assert list(option.type.choices) == [m.value for m in kind]
        assert option.type.convert(option.type.choices[-1], option, None) is list(kind)[-1]


# --- the source ------------------------------------------------------------------------------

def _literals(node: ast.AST) -> Iterator[ast.Constant]:
    """The literals in an expression, but None/True/False, a unit's factor (1000, 1/1000) and
    a subscript's index."""
    skip = {id(n) for sub in ast.walk(node) if isinstance(sub, ast.Subscript)
            for n in ast.walk(sub.slice)}
    for sub in ast.walk(node):
        if isinstance(sub, ast.Constant) and id(sub) not in skip \
                and not any(sub.value is v for v in (None, True, False)) \
                and sub.value not in (UNIT_FACTOR, 1 / UNIT_FACTOR):
            yield sub


def _is_choice(call: ast.Call) -> bool:
    f = call.func
    return (isinstance(f, ast.Attribute) and f.attr == "Choice") or \
        (isinstance(f, ast.Name) and f.id == "OneOf")


def _numbers_and_choices(node: ast.AST) -> Iterator[ast.Constant]:
    """In a ``type=``: a number (a bound), or a name spelled out in a choice."""
    for c in _literals(node):
        if isinstance(c.value, int | float):
            yield c
    for sub in ast.walk(node):
        if isinstance(sub, ast.Call) and _is_choice(sub):
            yield from (c for c in _literals(sub) if isinstance(c.value, str))


def _option_calls(tree: ast.Module) -> Iterator[ast.Call]:
    for node in ast.walk(tree):
        if isinstance(node, ast.Call) and isinstance(node.func, ast.Attribute) \
                and node.func.attr in ("option", "argument"):
            yield node


CMD_FILES = sorted(PIPELINE.glob("*_cmd.py"))


@pytest.mark.parametrize("path", CMD_FILES, ids=[p.name for p in CMD_FILES])
def test_no_command_states_a_default_a_bound_or_a_choice(path: Path) -> None:
    tree = ast.parse(path.read_text())
    found = []
    for call in _option_calls(tree):
        for kw in call.keywords:
            if kw.arg == "default":
                found += [(kw.arg, c) for c in _literals(kw.value)]
            if kw.arg == "type":
                found += [(kw.arg, c) for c in _numbers_and_choices(kw.value)]
    for node in tree.body:                  # the module's names: option types, bounds
        if isinstance(node, ast.Assign | ast.AnnAssign) and node.value is not None:
            found += [("name", c) for c in _numbers_and_choices(node.value)]
    assert not found, "; ".join(f"{path.name}:{c.lineno} {what} {c.value!r}"
                                for what, c in found)


def test_the_rule_sees_a_literal() -> None:
    """The source check finds what it is for (so that it cannot pass by reading nothing)."""
    tree = ast.parse('@click.option("--n", type=bounded_int(1), default=4)\n'
                     '@click.option("--c", type=click.Choice(["a", "b"]), default="a")\n'
                     '@click.option("--t", type=T, default=D.t_s * 1e3)\ndef f(): ...\n')
    calls = list(_option_calls(tree))
    default = [c.value for call in calls for kw in call.keywords if kw.arg == "default"
               for c in _literals(kw.value)]
    types = [c.value for call in calls for kw in call.keywords if kw.arg == "type"
             for c in _numbers_and_choices(kw.value)]
    assert default == [4, "a"] and types == [1, "a", "b"]
    assert math.isclose(_scaled(0.02, UNIT_FACTOR), 20.0)


def test_the_help_names_every_command() -> None:
    """``pipeline --help``'s own text (not click's list) places every command."""
    words = set(re.findall(r"[a-z-]+", cli.help or ""))
    assert set(COMMANDS) <= words, set(COMMANDS) - words

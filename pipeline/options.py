"""Options shared by several commands, so each is spelled and documented once."""

from __future__ import annotations

import math
from collections.abc import Callable, Iterable
from enum import Enum
from pathlib import Path
from typing import Any, cast

import click

from core.atomic import same_path
from core.bounds import Bound, one_of
from core.errors import BadInput
from core.protocol import FOOTPRINT_SIDE
from core.recording import default_rrd_path
from train.generic_model import resolve as resolve_model


def rrd_option(f: Callable[..., Any]) -> Callable[..., Any]:
    """``--rrd PATH`` (default: beside the output) and ``--no-rrd``."""
    f = click.option(
        "--no-rrd", is_flag=True, help="Do not write a rerun recording."
    )(f)
    return click.option(
        "--rrd", type=click.Path(dir_okay=False, path_type=Path), default=None,
        help="Rerun recording to write (default: beside the output, .rrd).",
    )(f)


def resolve_rrd(out: Path, rrd: Path | None, no_rrd: bool,
                folder: bool | None = None) -> Path | None:
    """The recording path a stage writes, or None with ``--no-rrd``.

    The default goes beside ``out`` (:func:`~core.recording.default_rrd_path`), or inside
    it when ``out`` is a folder: ``folder`` says so; None: when one exists there or the running
    command declares ``out`` as one (``click.Path(file_okay=False)``, as synth's OUT_DIR). An
    ``--rrd`` naming the ``--out`` file is bad input.
    """
    if no_rrd:
        return None
    if folder is None:
        folder = out.is_dir() or _declared_folder(out)
    path = rrd if rrd is not None else default_rrd_path(out, folder)
    if same_path(path, out):
        raise BadInput(out, "--rrd and --out name the same file")
    return path


def _declared_folder(out: Path) -> bool:
    """Whether the running click command takes ``out`` through a folder-only path parameter."""
    ctx = click.get_current_context(silent=True)
    if ctx is None:
        return False
    return any(isinstance(p.type, click.Path) and not p.type.file_okay
               and p.name is not None and ctx.params.get(p.name) == out
               for p in ctx.command.params)


def seed_option(default: int) -> Callable[[Callable[..., Any]], Callable[..., Any]]:
    """``--seed N``: every random choice of the command derives from it; ``default`` is the
    seed field of the command's settings."""
    return click.option("--seed", type=int, default=default, show_default=True,
                        help="Random seed; same seed, same bytes of data.")


class _OneLineRange:
    """What a bounded click type shares: its :class:`~core.bounds.Bound`, the range check and
    its one-line refusal."""

    bound: Bound

    def _check(self, x: float, value: Any, param: click.Parameter | None) -> None:
        """Refuse ``x`` (typed as ``value``) outside the range: BadInput naming the option."""
        self.bound.check(_option_name(param), x, f"{value}")

    def describe(self) -> str:
        """The accepted range in words, e.g. ``in (0, 1]`` or ``> 0``."""
        return self.bound.describe()

    def _describe_range(self) -> str:
        """The range in --help (click's form), nothing when there is none."""
        if self.min is None and self.max is None:  # type: ignore[attr-defined]
            return ""
        return super()._describe_range()  # type: ignore[misc]


class FiniteFloat(_OneLineRange, click.FloatRange):
    """A finite float within optional bounds; anything else is one line naming the option.

    NaN, inf and out-of-range values are refused as :class:`~core.errors.BadInput` (the CLI
    prints ``error: --lr nan: ...`` and exits with status 2), not click's three-line usage
    error, and never reach a stage where they would surface as a traceback or a misleading
    "diverged". ``why`` (optional) is appended to a range refusal: what the bound protects.
    A FloatRange, so that --help shows the range as click does (``[default: 7.5; 0<x<=1000]``).
    """

    def __init__(self, min: float | None = None, max: float | None = None,  # noqa: A002
                 min_open: bool = False, max_open: bool = False, unit: str = "",
                 why: str = "") -> None:
        click.FloatRange.__init__(self, min, max, min_open, max_open)
        self.bound = Bound(min, max, min_open, max_open, unit, why)

    def convert(self, value: Any, param: click.Parameter | None,
                ctx: click.Context | None) -> float:
        """``value`` as a float, or BadInput naming the option and what is wrong."""
        name = _option_name(param)
        try:
            x = float(value)
        except (TypeError, ValueError):
            raise BadInput(None, f"{name} {value!r}: not a number") from None
        if not math.isfinite(x):
            raise BadInput(None, f"{name} {value}: not a finite number")
        self._check(x, f"{x:g}", param)
        return x

    def get_metavar(self, param: click.Parameter, ctx: click.Context | None = None) -> str:
        return "FLOAT"


class BoundedInt(_OneLineRange, click.IntRange):
    """A whole number within optional bounds, refused in one line (as :class:`FiniteFloat`)."""

    def __init__(self, min: int | None = None, max: int | None = None,  # noqa: A002
                 unit: str = "", why: str = "") -> None:
        click.IntRange.__init__(self, min, max)
        self.bound = Bound(min, max, unit=unit, why=why, whole=True)

    def convert(self, value: Any, param: click.Parameter | None,
                ctx: click.Context | None) -> int:
        """``value`` as an int, or BadInput naming the option and what is wrong."""
        try:
            x = int(value)
        except (TypeError, ValueError, OverflowError):
            raise BadInput(None, f"{_option_name(param)} {value!r}: not a whole number") \
                from None
        self._check(x, x, param)
        return x

    def get_metavar(self, param: click.Parameter, ctx: click.Context | None = None) -> str:
        return "INTEGER"


def ranged(bound: Bound, factor: float = 1.0, unit: str | None = None
           ) -> FiniteFloat | BoundedInt:
    """The click type of a setting's :class:`~core.bounds.Bound` (a whole number's, or a
    float's); an option in another unit than the setting's gives the ``factor`` of it to
    one of the setting's and its ``unit`` (ms for s: 1e3, "ms")."""
    if factor != 1.0:
        bound = bound.scaled(factor, bound.unit if unit is None else unit)
    if bound.whole:
        lo = None if bound.min is None else math.floor(bound.min) + 1 if bound.min_open \
            else math.ceil(bound.min)
        hi = None if bound.max is None else math.ceil(bound.max) - 1 if bound.max_open \
            else math.floor(bound.max)
        return BoundedInt(lo, hi, bound.unit, bound.why)
    return FiniteFloat(bound.min, bound.max, bound.min_open, bound.max_open, bound.unit,
                       bound.why)


class OneOf(click.Choice):
    """One of fixed choices: an enum's values (the value is then its member) or the names the
    code branches on; anything else is refused in one line naming the option."""

    def __init__(self, choices: type[Enum] | Iterable[str]) -> None:
        self.kind = choices if isinstance(choices, type) and issubclass(choices, Enum) else None
        super().__init__([str(m.value) for m in self.kind] if self.kind is not None
                         else [str(c) for c in choices])

    def convert(self, value: Any, param: click.Parameter | None,
                ctx: click.Context | None) -> Any:
        """``value`` (its member, with an enum), or BadInput naming the option."""
        if self.kind is not None:
            return one_of(self.kind, value, _option_name(param))
        if value not in self.choices:
            raise BadInput(None, f"{_option_name(param)} {value!r}: must be one of "
                                 f"{', '.join(dict.fromkeys(map(str, self.choices)))}")
        return value


class Parsed(click.ParamType):
    """Text that the command's own parser reads (``parse``, refusing in one line with
    :class:`~core.errors.BadInput`), checked as the options are parsed rather than when the
    stage reaches it. The value is what ``parse`` returns, or with ``keep_text`` the text
    itself (the settings hold the text; the parse only checks it)."""

    def __init__(self, name: str, parse: Callable[[str], Any], keep_text: bool = False) -> None:
        self.name, self.parse, self.keep_text = name, parse, keep_text

    def convert(self, value: Any, param: click.Parameter | None,
                ctx: click.Context | None) -> Any:
        """``value`` parsed (or checked), or BadInput naming what is wrong."""
        if not isinstance(value, str):          # a default already in its parsed form
            return value
        parsed = self.parse(value)
        return value if self.keep_text else parsed

    def get_metavar(self, param: click.Parameter, ctx: click.Context | None = None) -> str:
        return self.name


class SizeMM(click.ParamType):
    """A footprint ``LxW`` in mm (e.g. ``150x80``), as metres, each side within
    :data:`core.protocol.FOOTPRINT_SIDE`; anything else one line."""

    name = "LxW"

    def convert(self, value: Any, param: click.Parameter | None,
                ctx: click.Context | None) -> tuple[float, float]:
        """``value`` as (L, W) in m, or BadInput naming the option and what is wrong."""
        if isinstance(value, tuple):
            return value
        parts = str(value).lower().split("x")
        try:
            sizes = [float(v) * 1e-3 for v in parts]
        except ValueError:
            sizes = []
        side = FOOTPRINT_SIDE
        if len(sizes) != 2 or not all(math.isfinite(v) and side.holds(v) for v in sizes):
            mm = side.scaled(1e3, "")
            raise BadInput(None, f"{_option_name(param)} {value!r}: expected LxW, two lengths "
                                 f"in mm {mm.describe().removeprefix('in ')}, e.g. 150x80")
        return sizes[0], sizes[1]


SIZE_MM = SizeMM()


def _option_name(param: click.Parameter | None) -> str:
    """The option as the user typed it (``--lr``), or the argument's name."""
    if param is None:
        return "value"
    opts = getattr(param, "opts", None) or []
    longest = max(opts, key=len) if opts else (param.name or "value")
    return longest if longest.startswith("-") else longest.upper()


class Checkpoint(click.ParamType):
    """A trained model: an existing checkpoint (or, with ``folder``, a run folder), or
    ``generic`` / ``generic-curved``, the generic models shipped with the package
    (:mod:`train.generic_model`)."""

    name = "PATH|generic|generic-curved"

    def __init__(self, folder: bool = False) -> None:
        self.path = click.Path(exists=True, dir_okay=folder, path_type=Path)

    def convert(self, value: object, param: click.Parameter | None,
                ctx: click.Context | None) -> Path:
        if isinstance(value, Path):
            return value
        # click.Path(path_type=Path) converts to a Path; its annotation is the wider os.PathLike
        return cast(Path, self.path.convert(str(resolve_model(str(value))), param, ctx))

"""The commands a QTM real-time client sends: written by the live client
(:func:`command_text`), read by the replay (:func:`parse_command`), and the server's greeting.

Commands are text, case-insensitive, words separated by spaces (protocol documentation). The
replay understands ``Version [X.Y]``, ``GetParameters <sections>`` (``All`` or any of
``General 3D Analog Force``), ``StreamFrames <frames> <components>`` (frames ``AllFrames``,
``Frequency:N`` or ``FrequencyDivisor:N``; components any of ``3D 3DNoLabels Analog Force``),
``StreamFrames Stop``, ``GetCurrentFrame <components>``, ``GetState``, ``ByteOrder``,
``QTMVersion`` and ``ByeBye``. Anything else is :class:`Refused` with the error text the
server sends back.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

from live.protocol.packets import Component
from live.protocol.parameters import SECTIONS

GREETING = "QTM RT Interface connected"     # a server's first words to a client
# the components' and sections' words as QTM's documentation writes them (read in any case)
COMPONENT_WORDS = {Component.THREE_D: "3D", Component.THREE_D_NO_LABELS: "3DNoLabels",
                   Component.ANALOG: "Analog", Component.FORCE: "Force"}
COMPONENTS = {word.lower(): c for c, word in COMPONENT_WORDS.items()}
SECTION_WORDS = {"general": "General", "3d": "3D", "analog": "Analog", "force": "Force"}
# what QTM streams that a replayed session has nothing for
NOT_SERVED = {"2d", "2dlin", "3dres", "3dnolabelsres", "analogsingle", "forcesingle", "6d",
              "6dres", "6deuler", "6deulerres", "gazevector", "eyetracker", "image",
              "timecode", "skeleton", "skeleton:global", "calibration"}
# commands without arguments, as they are written
PLAIN_WORDS = {"getstate": "GetState", "byteorder": "ByteOrder", "qtmversion": "QTMVersion",
               "byebye": "ByeBye"}
PLAIN = set(PLAIN_WORDS)


class Refused(ValueError):
    """A command the replay does not carry out; ``str()`` is the error packet's text."""


@dataclass(frozen=True)
class Version:
    """``Version``: ask the protocol version (``None``) or set it."""

    number: str | None


@dataclass(frozen=True)
class GetParameters:
    """``GetParameters``: the sections of :data:`live.protocol.parameters.SECTIONS` asked."""

    sections: tuple[str, ...]


@dataclass(frozen=True)
class StreamFrames:
    """``StreamFrames``: every ``divisor``-th frame, or frames at ``frequency_hz``."""

    components: tuple[Component, ...]
    divisor: int = 1
    frequency_hz: float | None = None

    def step(self, rate_hz: float) -> int:
        """Frames between two sent, at the recording's ``rate_hz``."""
        if self.frequency_hz is None:
            return self.divisor
        return max(1, round(rate_hz / self.frequency_hz))


@dataclass(frozen=True)
class StopStreaming:
    """``StreamFrames Stop``."""


@dataclass(frozen=True)
class GetCurrentFrame:
    """``GetCurrentFrame``: one frame of these components."""

    components: tuple[Component, ...]


@dataclass(frozen=True)
class Plain:
    """A command without arguments: ``getstate``, ``byteorder``, ``qtmversion``, ``byebye``."""

    name: str


Command = Version | GetParameters | StreamFrames | StopStreaming | GetCurrentFrame | Plain


def command_text(command: Command) -> str:
    """The text a client sends for ``command`` (what :func:`parse_command` reads back)."""
    match command:
        case Version(number=None):
            return "Version"
        case Version(number=number):
            return f"Version {number}"
        case GetParameters(sections=sections):
            return "GetParameters " + " ".join(SECTION_WORDS[s] for s in sections)
        case StreamFrames(components=components, divisor=divisor, frequency_hz=hz):
            frames = "AllFrames" if hz is None and divisor == 1 else \
                f"FrequencyDivisor:{divisor}" if hz is None else f"Frequency:{hz:g}"
            return f"StreamFrames {frames} {_words(components)}"
        case StopStreaming():
            return "StreamFrames Stop"
        case GetCurrentFrame(components=components):
            return f"GetCurrentFrame {_words(components)}"
        case Plain(name=name):
            return PLAIN_WORDS[name]
    raise TypeError(f"not a command: {command!r}")


def _words(components: tuple[Component, ...]) -> str:
    return " ".join(COMPONENT_WORDS[c] for c in components)


def parse_command(text: str) -> Command:
    """The command in ``text``; :class:`Refused` with the reply's text otherwise."""
    words = text.lower().split()
    if not words:
        raise Refused("Parse error")
    name, args = words[0], words[1:]
    if name in PLAIN and not args:
        return Plain(name)
    if name == "version" and len(args) <= 1:
        return Version(args[0] if args else None)
    if name == "getparameters" and args:
        return GetParameters(_sections(args))
    if name == "streamframes" and args == ["stop"]:
        return StopStreaming()
    if name == "streamframes" and len(args) >= 2:
        return _stream_frames(args[0], args[1:])
    if name == "getcurrentframe" and args:
        return GetCurrentFrame(_components(args))
    raise Refused("Parse error")


def _sections(args: list[str]) -> tuple[str, ...]:
    if "all" in args:
        return SECTIONS
    unknown = [a for a in args if a not in SECTIONS]
    if unknown:
        raise Refused(f"GetParameters {' '.join(unknown)}: not served by the replay "
                      f"(it serves {', '.join(SECTIONS)})")
    return tuple(s for s in SECTIONS if s in args)


def _components(args: list[str]) -> tuple[Component, ...]:
    served = [a for a in args if a in COMPONENTS]
    absent = [a for a in args if a in NOT_SERVED]
    if absent:
        raise Refused(f"{' '.join(absent)}: not served by the replay (it serves "
                      f"{', '.join(COMPONENTS)})")
    if len(served) != len(args):
        raise Refused("Parse error")
    return tuple(dict.fromkeys(COMPONENTS[a] for a in served))


def _stream_frames(frames: str, args: list[str]) -> StreamFrames:
    if any(a.startswith("udp") for a in args):
        raise Refused("StreamFrames over UDP: not served by the replay (TCP only)")
    components = _components(args)
    if frames == "allframes":
        return StreamFrames(components)
    kind, _, value = frames.partition(":")
    number = _positive(value)
    if kind == "frequencydivisor" and number.is_integer():
        return StreamFrames(components, divisor=int(number))
    if kind == "frequency":
        return StreamFrames(components, frequency_hz=number)
    raise Refused("Parse error")


def _positive(text: str) -> float:
    try:
        x = float(text)
    except ValueError:
        raise Refused("Parse error") from None
    if not (math.isfinite(x) and x > 0):
        raise Refused("Parse error")
    return x

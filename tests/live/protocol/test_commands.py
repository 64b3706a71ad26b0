"""The commands a QTM RT client sends, read case-insensitively; what the replay does not serve
is refused with the text of the error packet it sends back."""

from __future__ import annotations

import pytest

import live.protocol.commands as rc
from live.protocol.packets import Component as C


@pytest.mark.parametrize("text, command", [
    ("Version 1.25", rc.Version("1.25")),
    ("version", rc.Version(None)),
    ("GetParameters General 3D Analog Force",
     rc.GetParameters(("general", "3d", "analog", "force"))),
    ("getparameters force 3d", rc.GetParameters(("3d", "force"))),
    ("GetParameters All", rc.GetParameters(("general", "3d", "analog", "force"))),
    ("StreamFrames AllFrames 3D 3DNoLabels Analog Force",
     rc.StreamFrames((C.THREE_D, C.THREE_D_NO_LABELS, C.ANALOG, C.FORCE))),
    ("streamframes frequencydivisor:5 analog", rc.StreamFrames((C.ANALOG,), divisor=5)),
    ("StreamFrames Frequency:100 3d 3d", rc.StreamFrames((C.THREE_D,), frequency_hz=100.0)),
    ("StreamFrames Stop", rc.StopStreaming()),
    ("GetCurrentFrame 3D Analog", rc.GetCurrentFrame((C.THREE_D, C.ANALOG))),
    ("ByeBye", rc.Plain("byebye")), ("GetState", rc.Plain("getstate")),
])
def test_commands_are_read(text, command):
    assert rc.parse_command(text) == command


@pytest.mark.parametrize("text, words", [
    ("", "Parse error"), ("Take control", "Parse error"), ("StreamFrames", "Parse error"),
    ("StreamFrames AllFrames 3D banana", "Parse error"),
    ("StreamFrames FrequencyDivisor:0 3D", "Parse error"),
    ("StreamFrames FrequencyDivisor:2.5 3D", "Parse error"),
    ("StreamFrames Frequency:nan 3D", "Parse error"),
    ("StreamFrames AllFrames 6D", "6d: not served by the replay"),
    ("StreamFrames AllFrames UDP:4545 3D", "over UDP: not served"),
    ("GetParameters 6D Skeleton", "GetParameters 6d skeleton: not served"),
    ("Version 1.25 1.26", "Parse error"),
])
def test_what_is_not_served_is_refused(text, words):
    with pytest.raises(rc.Refused, match=words):
        rc.parse_command(text)


def test_frequency_becomes_a_step_at_the_recording_rate():
    assert rc.StreamFrames((C.THREE_D,), frequency_hz=100.0).step(500.0) == 5
    assert rc.StreamFrames((C.THREE_D,), frequency_hz=1e6).step(500.0) == 1
    assert rc.StreamFrames((C.THREE_D,), divisor=3).step(500.0) == 3


@pytest.mark.parametrize("command", [
    rc.Version("1.25"), rc.Version(None), rc.GetParameters(("general", "3d", "analog", "force")),
    rc.StreamFrames((C.THREE_D, C.ANALOG)), rc.StreamFrames((C.THREE_D, C.FORCE), divisor=4),
    rc.StreamFrames((C.THREE_D_NO_LABELS,), frequency_hz=100.0), rc.StopStreaming(),
    rc.GetCurrentFrame((C.THREE_D,)), rc.Plain("byebye"), rc.Plain("qtmversion"),
])
def test_what_the_client_writes_the_replay_reads_back(command):
    assert rc.parse_command(rc.command_text(command)) == command


def test_the_client_writes_the_documented_words():
    assert rc.command_text(rc.StreamFrames((C.THREE_D, C.ANALOG))) == \
        "StreamFrames AllFrames 3D Analog"
    assert rc.command_text(rc.GetParameters(("general", "3d", "analog", "force"))) == \
        "GetParameters General 3D Analog Force"

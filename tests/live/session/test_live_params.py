"""The settings of ``pipeline live`` and ``pipeline replay`` refuse, as they are made, what
their command lines refuse: the same values, at the same bounds, in one line each; and
``HOST[:PORT]`` is read with QTM's port and this machine by default."""

from __future__ import annotations

import math

import pytest
from click.testing import CliRunner

from core.errors import BadInput
from live.protocol.address import DEFAULT_HOST, QTM_PORT, parse_address
from live.replay.replay_params import ReplayParams
from live.session.live_params import LiveParams
from pipeline.cli import cli

# (setting, its option, a value refused at the bound, one accepted at it)
LIVE_BOUNDS = [("timeout_s", "--timeout", 600.5, 600.0), ("timeout_s", "--timeout", 0.0, 0.01),
               ("reconnect_s", "--reconnect", 3600.5, 3600.0),
               ("reconnect_s", "--reconnect", -0.5, 0.0),
               ("duration_s", "--duration", 0.0, 0.01)]


@pytest.mark.parametrize(("field", "option", "refused", "accepted"), LIVE_BOUNDS)
def test_live_settings_and_options_share_their_bounds(tmp_path, field, option, refused,
                                                      accepted) -> None:
    with pytest.raises(BadInput, match=f"{field} {refused:g}"):
        LiveParams(**{field: refused})
    LiveParams(**{field: accepted})
    res = CliRunner().invoke(cli, ["live", str(tmp_path), "--out", str(tmp_path / "o"),
                                   option, str(refused)])
    assert res.exit_code == 2 and len(res.stderr.strip().splitlines()) == 1
    assert f"{option} {refused:g}" in res.stderr


@pytest.mark.parametrize("settings", [{"timeout_s": math.nan}, {"reconnect_s": math.inf},
                                      {"duration_s": math.nan}, {"port": 0}, {"port": 65536}])
def test_live_settings_refuse_what_is_no_number_or_port(settings) -> None:
    with pytest.raises(BadInput, match="must be"):
        LiveParams(**settings)


@pytest.mark.parametrize(("settings", "words"), [
    ({"port": -1}, "port -1: must be in [0, 65535]"),
    ({"port": 65536}, "port 65536: must be in [0, 65535]"),
    ({"speed": 0.0}, "speed 0.0: must be in (0, 1000]"),
    ({"speed": math.nan}, "speed nan"), ({"speed": 1000.5}, "speed 1000.5"),
    ({"max_clients": -1}, "max_clients -1: must be >= 0"),
])
def test_replay_settings_refuse_what_its_command_refuses(settings, words) -> None:
    with pytest.raises(BadInput, match=words.replace("(", r"\(").replace("[", r"\[")):
        ReplayParams(**settings)
    assert ReplayParams(port=0, speed=1000.0).port == 0          # 0: any free port


def test_an_address_is_host_and_port_with_qtms_by_default() -> None:
    assert parse_address("lab-pc") == ("lab-pc", QTM_PORT)
    assert parse_address("lab-pc:22224") == ("lab-pc", 22224)
    assert parse_address(":22224") == (DEFAULT_HOST, 22224)
    for text in ("lab-pc:0", "lab-pc:65536", "lab-pc:x", "lab-pc:"):
        with pytest.raises(BadInput, match="is not a port number"):
            parse_address(text)
    assert LiveParams().host == ReplayParams().host == DEFAULT_HOST
    assert LiveParams().port == ReplayParams().port == QTM_PORT

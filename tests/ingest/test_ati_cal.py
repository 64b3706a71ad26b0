"""ATI .cal reader/writer: the real Nano17 file against its own text, unit conversion, the
write/read round trip, and files that do not make a 6x6 matrix."""

from __future__ import annotations

import re

import numpy as np
import pytest
from helpers.paths import REAL_SAMPLES

from core.errors import BadInput
from core.series import AtiCalibration
from core.units import channel_units, length_scale, unit_to_si
from ingest.ati_cal import read_ati_cal, write_ati_cal

pytestmark = pytest.mark.usefixtures("real_samples")

CAL = REAL_SAMPLES / "ati" / \
    "nano17_FT14048_SI-50-0.5.cal"
LBF = 4.4482216152605


def _user_axes(text: str) -> np.ndarray:
    """The UserAxis rows read with a regular expression (independent of the XML reader)."""
    rows = re.findall(r'<UserAxis Name="(\w+)" values="([^"]*)"', text)
    assert [r[0] for r in rows] == ["Fx", "Fy", "Fz", "Tx", "Ty", "Tz"]
    return np.array([[float(v) for v in r[1].split()] for r in rows])


def test_real_nano17_calibration():
    c = read_ati_cal(CAL)
    assert c.serial == "FT14048" and c.body_style == "Nano17"
    assert c.calibration == "SI-50-0.5"
    assert c.force_units == "N" and c.torque_units == "N-mm"
    assert c.matrix[0, 0] == pytest.approx(-0.00280)                      # Fx, gauge 0 (N/V)
    assert c.matrix[3, 1] == pytest.approx(48.31227e-3)                   # Tx: N-mm -> N*m
    raw = _user_axes(CAL.read_text())
    assert c.matrix == pytest.approx(raw * np.array([1, 1, 1, 1e-3, 1e-3, 1e-3])[:, None])
    assert c.max_load == pytest.approx([50, 50, 70, 0.5, 0.5, 0.5])
    assert c.meta["calibration"]["CalDate"] == "8/7/2013"


def test_round_trip_of_the_real_file(tmp_path):
    c = read_ati_cal(CAL)
    write_ati_cal(tmp_path / "copy.cal", c)
    text = (tmp_path / "copy.cal").read_text()
    assert np.array_equal(_user_axes(text), _user_axes(CAL.read_text()))  # same digits
    back = read_ati_cal(tmp_path / "copy.cal")
    assert np.array_equal(back.matrix, c.matrix) and np.array_equal(back.max_load, c.max_load)
    assert (back.serial, back.calibration, back.body_style) == ("FT14048", "SI-50-0.5", "Nano17")


def test_round_trip_of_a_new_calibration(tmp_path):
    rng = np.random.default_rng(5)
    matrix = np.vstack([rng.normal(0, 1, (3, 6)), rng.normal(0, 0.01, (3, 6))])
    c = AtiCalibration(source="twin", serial="FT99999", body_style="Nano17",
                       calibration="SI-12-0.12", matrix=matrix,
                       max_load=np.array([12, 12, 17, 0.12, 0.12, 0.12]),
                       force_units="N", torque_units="N*m")
    write_ati_cal(tmp_path / "FT99999.cal", c)
    back = read_ati_cal(tmp_path / "FT99999.cal")
    assert np.abs(back.matrix[:3] - matrix[:3]).max() <= 5e-6                 # 5 decimals, N
    assert np.abs(back.matrix[3:] - matrix[3:]).max() <= 5e-9                 # 5 decimals, N-mm
    assert back.max_load == pytest.approx(c.max_load)
    assert back.torque_units == "N-mm" and back.calibration == "SI-12-0.12"


def _cal(rows: dict[str, str], force: str = "N", torque: str = "N-mm") -> str:
    axes = "\n".join(f'<UserAxis Name="{k}" values="{v}" max="10"/>' for k, v in rows.items())
    return (f'<?xml version="1.0"?><FTSensor Serial="X1" BodyStyle="Nano17">'
            f'<Calibration PartNumber="P" ForceUnits="{force}" TorqueUnits="{torque}">'
            f"{axes}</Calibration></FTSensor>")


SIX = {a: "1 2 3 4 5 6" for a in ("Fx", "Fy", "Fz", "Tx", "Ty", "Tz")}


def test_imperial_units_convert_rows_and_max(tmp_path):
    p = tmp_path / "lb.cal"
    p.write_text(_cal(SIX, force="lbf", torque="lbf-in"))
    c = read_ati_cal(p)
    assert c.matrix[0, 5] == pytest.approx(6 * LBF)
    assert c.matrix[5, 0] == pytest.approx(LBF * 0.0254)
    assert c.max_load == pytest.approx([10 * LBF] * 3 + [10 * LBF * 0.0254] * 3)


@pytest.mark.parametrize(("rows", "units", "message"), [
    ({k: v for k, v in SIX.items() if k != "Tz"}, ("N", "N-mm"), "no UserAxis row for Tz"),
    ({**SIX, "Fy": "1 2 3 4 5"}, ("N", "N-mm"), "UserAxis Fy has 5 values"),
    ({**SIX, "Fz": "1 2 x 4 5 6"}, ("N", "N-mm"), "not a list of numbers"),
    (SIX, ("N", "N"), "not a torque unit"),
    (SIX, ("stone", "N-mm"), "unknown unit"),
    (SIX, ("mV", "N-mm"), "ForceUnits 'mV' is not a force unit"),
    (SIX, ("N-mm", "N-mm"), "ForceUnits 'N-mm' is not a force unit"),
    (SIX, ("N", "V"), "TorqueUnits 'V' is not a torque unit"),
    ({**SIX, "Ty": "1 2 nan 4 5 6"}, ("N", "N-mm"), "UserAxis Ty has a non-finite value"),
    ({**SIX, "Fx": "1 2 3 inf 5 6"}, ("N", "N-mm"), "UserAxis Fx has a non-finite value"),
])
def test_bad_calibration_files(tmp_path, rows, units, message):
    p = tmp_path / "bad.cal"
    p.write_text(_cal(rows, *units))
    with pytest.raises(BadInput, match=message) as e:
        read_ati_cal(p)
    assert str(p) in str(e.value)


def test_bad_not_an_ati_file(tmp_path):
    for name, text in (("a.cal", "<html><body/></html>"), ("b.cal", "not xml at all <")):
        (tmp_path / name).write_text(text)
        with pytest.raises(BadInput, match=name):
            read_ati_cal(tmp_path / name)


def test_channel_units():
    assert channel_units(None, "gauge", 6) == ["V"] * 6
    assert channel_units(None, "wrench", 6) == ["N", "N", "N", "N*m", "N*m", "N*m"]
    assert channel_units("mV", "gauge", 2) == ["mV", "mV"]
    assert channel_units("N, lbf-in", "wrench", 2) == ["N", "lbf-in"]
    for units, kind, words in ((5, "gauge", "a unit or a list"), (["V", 3], "gauge", "list"),
                               ("N", "gauge", "does not fit"), ("V,V", "gauge", "2 units"),
                               ("V", "volts", "kind must be")):
        with pytest.raises(ValueError, match=words):
            channel_units(units, kind, 6)
    assert length_scale("cm") == 1e-2
    with pytest.raises(ValueError, match="not a length unit"):
        length_scale("in")


def test_unit_spellings():
    assert unit_to_si("N*m") == unit_to_si("Nm") == unit_to_si("N-m") == (1.0, "N*m")
    assert unit_to_si("Nmm") == unit_to_si("N·mm") == (1e-3, "N*m")
    assert unit_to_si("mV") == (1e-3, "V")
    with pytest.raises(ValueError):
        unit_to_si("parsec")

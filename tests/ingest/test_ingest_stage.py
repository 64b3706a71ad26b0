"""`pipeline ingest`: a small session folder in the lab formats to MCAP and back, and bad input."""

from __future__ import annotations

import shutil
from pathlib import Path

import numpy as np
import pytest
from click.testing import CliRunner
from helpers.paths import REAL_SAMPLES
from helpers.spoiled_session import folder_hash, replace_text

from core.provenance import sha256_file
from core.recording import rrd_entities, rrd_has_blueprint, rrd_timelines
from ingest.mcap_io import read_raw_mcap
from pipeline.cli import cli

pytestmark = pytest.mark.usefixtures("real_samples")

REAL = REAL_SAMPLES
PHANTOM = [f"P{r}{c}" for r in range(5) for c in range(5)]
INDENTER = ["Ind 1", "Ind 2", "Ind 3", "Ind 4"]          # names with spaces, as QTM allows
LABELS = PHANTOM + INDENTER + ["stray"]
FRAMES, RATE = 120, 500
FORCE_SAMPLES = 250
GAPS = {(10, 3): "NaN", (11, 3): "NaN", (50, 26): "", (51, 26): "", (80, 7): "null"}


def mocap_mm(rng: np.random.Generator) -> np.ndarray:
    """Marker positions (frames, markers, 3) in mm, three decimals, NaN in the gaps."""
    grid = np.array([[20.0 * (i % 5), 20.0 * (i // 5), 32.0] for i in range(25)])
    base = np.vstack([grid, [[40, 40, 80], [60, 40, 80], [40, 60, 85], [50, 50, 110]],
                      [[-100, 0, 0]]])
    pos = base[None] + rng.normal(0, 0.2, (FRAMES, len(LABELS), 3)).cumsum(axis=0)
    pos = np.round(pos, 3)
    for f, m in GAPS:
        pos[f, m] = np.nan
    return pos


def write_tsv(path: Path, pos: np.ndarray, labels: list[str] = LABELS,
              frames: int | None = None) -> None:
    """A QTM 2026-style 3D export: header keys, an EVENT, a Frame/Time column line."""
    lines = [f"NO_OF_FRAMES\t{frames or pos.shape[0]}", "NO_OF_CAMERAS\t8",
             f"NO_OF_MARKERS\t{len(labels)}", f"FREQUENCY\t{RATE}", "NO_OF_ANALOG\t0",
             "ANALOG_FREQUENCY\t0", "DESCRIPTION\t--",
             "TIME_STAMP\t2026-11-21, 10:00:00.000\t1234.5", "DATA_INCLUDED\t3D",
             "EVENT\tTrigger\t21\t0.040", "MARKER_NAMES\t" + "\t".join(labels),
             "TRAJECTORY_TYPES\t" + "\t".join(["Measured"] * len(labels)),
             "Frame\tTime\t" + "\t".join(f"{n} {a}" for n in labels for a in "XYZ") + "\t"]
    for f in range(pos.shape[0]):
        cells = [str(f + 1), f"{f / RATE:.5f}"]
        for m in range(len(labels)):
            gap = GAPS.get((f, m))
            cells += [gap] * 3 if gap is not None else [f"{v:.3f}" for v in pos[f, m]]
        lines.append("\t".join(cells))
    path.write_text("\r\n".join(lines) + "\r\n")


def write_force(path: Path, rng: np.random.Generator) -> np.ndarray:
    """A 1 kHz gauge log: time (s), six volts, a trigger column; returns the values."""
    values = np.round(rng.normal(0, 0.5, (FORCE_SAMPLES, 6)), 6)
    trigger = (np.arange(FORCE_SAMPLES) % 100 < 5).astype(float)
    rows = ["time,G0,G1,G2,G3,G4,G5,trigger"]
    for i in range(FORCE_SAMPLES):
        rows.append(",".join([f"{i / 1000:.3f}", *(f"{v:.6f}" for v in values[i]),
                              f"{trigger[i]:g}"]))
    path.write_text("\n".join(rows) + "\n")
    return values


SESSION_TOML = """schema = "phantom.session"
schema_version = "1.0"
name = "tiny-session"

[mocap]
file = "trial_3d.tsv"
phantom_markers = [{phantom}]
indenter_markers = [{indenter}]
trigger_event = "Trigger"

[force]
file = "force.csv"
time_column = "time"
time_unit = "s"
kind = "gauge"
channels = ["G0", "G1", "G2", "G3", "G4", "G5"]
units = "V"
calibration = "FT14048.cal"
trigger_column = "trigger"
"""


def write_toml(folder: Path, phantom: list[str] = PHANTOM,
               indenter: list[str] = INDENTER) -> None:
    quote = lambda names: ", ".join(f'"{n}"' for n in names)  # noqa: E731
    (folder / "session.toml").write_text(
        SESSION_TOML.format(phantom=quote(phantom), indenter=quote(indenter)))


@pytest.fixture
def session(tmp_path) -> tuple[Path, np.ndarray, np.ndarray]:
    rng = np.random.default_rng(3)
    folder = tmp_path / "session"
    folder.mkdir()
    pos = mocap_mm(rng)
    write_tsv(folder / "trial_3d.tsv", pos)
    values = write_force(folder / "force.csv", rng)
    shutil.copy(REAL / "ati" / "nano17_FT14048_SI-50-0.5.cal", folder / "FT14048.cal")
    write_toml(folder)
    return folder, pos, values


def run(args: list[str]):
    return CliRunner().invoke(cli, ["-q", *args])


def test_ingest_round_trip(session, tmp_path):
    from ingest.ati_cal import read_ati_cal
    from ingest.detect import read_mocap

    folder, pos_mm, values = session
    before = folder_hash(folder)
    out, rrd = tmp_path / "out" / "tiny.mcap", tmp_path / "out" / "tiny.rrd"
    res = run(["ingest", str(folder), "--out", str(out), "--rrd", str(rrd)])
    assert res.exit_code == 0, res.output + res.stderr
    assert folder_hash(folder) == before
    s = read_raw_mcap(out)
    m = s.markers
    assert m.labels == LABELS and m.rate_hz == RATE and m.frames == FRAMES
    assert s.phantom_markers == PHANTOM and s.indenter_markers == INDENTER
    # positions within 1e-4 mm of the file, NaN exactly in the gaps
    np.testing.assert_allclose(m.positions * 1000.0, pos_mm, rtol=0, atol=1e-4)
    assert np.array_equal(np.isnan(m.positions).any(axis=2), np.isnan(pos_mm).any(axis=2))
    assert m.missing_samples() == len(GAPS)
    np.testing.assert_allclose(m.time_ns, np.arange(FRAMES) * 2_000_000, rtol=0, atol=1_000)
    direct = read_mocap(folder / "trial_3d.tsv")        # identical to what the reader gives
    assert np.array_equal(m.time_ns, direct.time_ns)
    assert np.array_equal(m.positions, direct.positions, equal_nan=True)
    assert [e for e, _ in m.events] == ["Trigger"] and s.trigger_event == "Trigger"
    f = s.force
    assert f.channels == [f"G{i}" for i in range(6)] and f.kind == "gauge" and f.units == ["V"] * 6
    np.testing.assert_allclose(f.values, values, rtol=0, atol=1e-9)
    np.testing.assert_allclose(f.time_ns, np.arange(FORCE_SAMPLES) * 1_000_000, rtol=0, atol=1)
    assert f.trigger is not None and f.trigger.sum() == 15
    assert np.array_equal(s.calibration.matrix, read_ati_cal(folder / "FT14048.cal").matrix)
    assert s.provenance["stage"] == "ingest"
    assert sorted(Path(p).name for p in s.provenance["inputs"]) == \
        ["FT14048.cal", "force.csv", "session.toml", "trial_3d.tsv"]
    assert all(sha256_file(p) == h for p, h in s.provenance["inputs"].items())
    assert "tiny.mcap" in res.output
    ents = rrd_entities(rrd)
    for name in PHANTOM:
        assert "Points3D" in ents[f"/mocap/phantom/{name}"]
    assert "Points3D" in ents["/mocap/indenter/Ind_1"]         # path-safe, no escapes
    assert "Points3D" in ents["/mocap/other/stray"]
    for i in range(6):                                          # one plot per unit: volts
        assert "SeriesLines" in ents[f"/force/V/G{i}"] and "Scalars" in ents[f"/force/V/G{i}"]
    assert "ViewCoordinates" in ents["/"] and rrd_timelines(rrd) == {"device_time"}
    for e, kind in [("/trigger/level", "Scalars"),
                    ("/quality/missing_markers", "Scalars"), ("/trails/phantom", "LineStrips3D"),
                    ("/trails/indenter", "LineStrips3D"), ("/mocap/events", "TextLog")]:
        assert kind in ents[e], e
    assert rrd_has_blueprint(rrd)


def test_default_rrd_and_no_rrd(session, tmp_path):
    folder, _, _ = session
    res = run(["ingest", str(folder), "--out", str(tmp_path / "a.mcap")])
    assert res.exit_code == 0, res.stderr
    assert (tmp_path / "a.rrd").is_file()
    res = run(["ingest", str(folder), "--out", str(tmp_path / "b.mcap"), "--no-rrd"])
    assert res.exit_code == 0 and (tmp_path / "b.mcap").is_file()
    assert not (tmp_path / "b.rrd").exists()


def _absent_marker(folder: Path) -> str:
    write_toml(folder, phantom=[*PHANTOM[:24], "P99"])
    return "trial_3d.tsv"


def _duplicate_marker(folder: Path) -> str:
    rng = np.random.default_rng(1)
    write_tsv(folder / "trial_3d.tsv", mocap_mm(rng), labels=[*LABELS[:-1], "P00"])
    return "trial_3d.tsv"


def _unknown_format(folder: Path) -> str:
    (folder / "trial_3d.tsv").write_bytes(b"\x00\x01garbage that is no lab format\n" * 20)
    return "trial_3d.tsv"


def _cal_not_6x6(folder: Path) -> str:
    cal = folder / "FT14048.cal"
    lines = cal.read_text().splitlines()
    cal.write_text("\n".join(x for x in lines if 'UserAxis Name="Tz"' not in x))
    return "FT14048.cal"


def _force_missing_column(folder: Path) -> str:
    path = folder / "force.csv"
    rows = [r.rsplit(",", 2)[0] for r in path.read_text().splitlines()]   # drop G5, trigger
    path.write_text("\n".join(rows) + "\n")
    return "force.csv"


def _force_text_in_numbers(folder: Path) -> str:
    path = folder / "force.csv"
    rows = path.read_text().splitlines()
    cells = rows[40].split(",")
    cells[2] = "abc"
    rows[40] = ",".join(cells)
    path.write_text("\n".join(rows) + "\n")
    return "force.csv"


def _force_time_not_increasing(folder: Path) -> str:
    path = folder / "force.csv"
    rows = path.read_text().splitlines()
    rows[60], rows[61] = rows[61], rows[60]
    path.write_text("\n".join(rows) + "\n")
    return "force.csv"


def _truncated_tsv(folder: Path) -> str:
    path = folder / "trial_3d.tsv"
    data = path.read_bytes()
    path.write_bytes(data[: int(len(data) * 0.6)])       # cut in the middle of a line
    return "trial_3d.tsv"


def _duplicate_in_toml(folder: Path) -> str:
    write_toml(folder, phantom=[*PHANTOM, "P00"])
    return "session.toml"


def _toml_edit(folder: Path, old: str, new: str) -> str:
    path = folder / "session.toml"
    text = path.read_text()
    assert old in text
    path.write_text(text.replace(old, new))
    return "session.toml"


def _toml_pivot_not_a_table(folder: Path) -> str:
    (folder / "pivot.tsv").write_bytes((folder / "trial_3d.tsv").read_bytes())
    return _toml_edit(folder, 'name = "tiny-session"', 'name = "tiny-session"\npivot = '
                                                         '"pivot.tsv"')


def _toml_units_not_text(folder: Path) -> str:
    return _toml_edit(folder, 'units = "V"', "units = 5")


def _toml_units_not_volts(folder: Path) -> str:
    return _toml_edit(folder, 'units = "V"', 'units = "N"')


def _toml_time_unit_list(folder: Path) -> str:
    return _toml_edit(folder, 'time_unit = "s"', 'time_unit = ["s"]')


def _toml_schema_version_2(folder: Path) -> str:
    return _toml_edit(folder, 'schema_version = "1.0"', 'schema_version = "2.0"')


def _force_row_with_extra_field(folder: Path) -> str:
    path = folder / "force.csv"
    rows = path.read_text().splitlines()
    rows[30] += ",0.5"                       # 9 fields under an 8-name header
    path.write_text("\n".join(rows) + "\n")
    return "force.csv:line 31"


def _cal_force_units_not_force(folder: Path) -> str:
    replace_text(folder / "FT14048.cal", 'ForceUnits="N"', 'ForceUnits="mV"')
    return "FT14048.cal"


def _cal_nan_value(folder: Path) -> str:
    cal = folder / "FT14048.cal"
    text = cal.read_text()
    i = text.index('values="', text.index('UserAxis Name="Fz"')) + len('values="')
    cal.write_text(text[:i] + "nan " + text[text.index(" ", i) + 1:])
    return "FT14048.cal"


def _mocap_infinite_coordinate(folder: Path) -> str:
    path = folder / "trial_3d.tsv"
    lines = path.read_bytes().decode().split("\r\n")
    cells = lines[20].split("\t")
    cells[4] = "inf"
    lines[20] = "\t".join(cells)
    path.write_text("\r\n".join(lines))
    return "trial_3d.tsv:line 21"


def _mocap_time_out_of_range(folder: Path) -> str:
    path = folder / "trial_3d.tsv"
    lines = path.read_bytes().decode().split("\r\n")
    cells = lines[-2].split("\t")
    cells[1] = "1e300"
    lines[-2] = "\t".join(cells)
    path.write_text("\r\n".join(lines))
    return f"trial_3d.tsv:line {len(lines) - 1}"


def _mocap_frequency_too_low(folder: Path) -> str:
    """An old-style export (no Frame/Time columns, timed by FREQUENCY) with a corrupt rate."""
    path = folder / "trial_3d.tsv"
    lines = path.read_bytes().decode().split("\r\n")
    head = [ln.replace(f"FREQUENCY\t{RATE}", "FREQUENCY\t1e-300") for ln in lines[:12]]
    rows = ["\t".join(ln.split("\t")[2:]) for ln in lines[13:]]   # drop column line, Frame, Time
    path.write_bytes("\r\n".join(head + rows).encode())
    return "trial_3d.tsv:line 4"


def _mocap_damaged_qtm_mat(folder: Path) -> str:
    from ingest.qtm_mat import write_qtm_mat

    tsv = folder / "trial_3d.tsv"
    mat = folder / "trial.mat"
    write_qtm_mat(mat, read_mocap_file(tsv), version="7")
    raw = bytearray(mat.read_bytes())
    raw[len(raw) // 2:len(raw) // 2 + 64] = bytes(64)    # damage inside the compressed data
    tsv.write_bytes(bytes(raw))                           # session.toml names trial_3d.tsv
    mat.unlink()
    return "trial_3d.tsv: cannot read the QTM struct"


def _mocap_c3d_cut_in_parameters(folder: Path) -> str:
    c3d = REAL / "c3d" / "qualisys_55markers_200hz.c3d"
    (folder / "trial_3d.tsv").write_bytes(c3d.read_bytes()[:520])
    return "trial_3d.tsv: truncated"


def read_mocap_file(path: Path):  # noqa: ANN201 - a MarkerSeries
    from ingest.detect import read_mocap

    return read_mocap(path)


BAD = [_absent_marker, _duplicate_marker, _unknown_format, _cal_not_6x6, _force_missing_column,
       _force_text_in_numbers, _force_time_not_increasing, _truncated_tsv, _duplicate_in_toml,
       _toml_pivot_not_a_table, _toml_units_not_text, _toml_units_not_volts,
       _toml_time_unit_list, _toml_schema_version_2,
       _force_row_with_extra_field, _cal_force_units_not_force, _cal_nan_value,
       _mocap_infinite_coordinate, _mocap_time_out_of_range, _mocap_frequency_too_low,
       _mocap_damaged_qtm_mat, _mocap_c3d_cut_in_parameters]


@pytest.mark.parametrize("spoil", BAD, ids=[f.__name__.strip("_") for f in BAD])
def test_bad_input(session, tmp_path, spoil):
    folder, _, _ = session
    culprit = spoil(folder)
    before = folder_hash(folder)
    out = tmp_path / "out" / "x.mcap"
    res = run(["ingest", str(folder), "--out", str(out)])
    assert res.exit_code == 2, (res.output, res.stderr, res.exception)
    lines = res.stderr.strip().splitlines()
    assert len(lines) == 1 and lines[0].startswith("error: ") and culprit in lines[0], lines
    assert f"{folder}/{culprit}" in lines[0] or culprit == "session.toml", lines
    assert "Traceback" not in res.stderr
    assert folder_hash(folder) == before
    assert not out.parent.exists() or not list(out.parent.iterdir())


def test_absent_markers_are_all_listed(session, tmp_path):
    folder, _, _ = session
    write_toml(folder, phantom=[*PHANTOM[:23], "P98", "P99"])
    res = run(["ingest", str(folder), "--out", str(tmp_path / "x.mcap")])
    assert res.exit_code == 2 and "P98" in res.stderr and "P99" in res.stderr


def test_rrd_and_out_naming_one_file_is_bad_input(session, tmp_path):
    folder, _, _ = session
    out = tmp_path / "o" / "x.mcap"
    for rrd in (out, tmp_path / "o" / ".." / "o" / "x.mcap"):
        res = run(["ingest", str(folder), "--out", str(out), "--rrd", str(rrd)])
        assert res.exit_code == 2, (res.output, res.stderr, res.exception)
        assert res.stderr.strip().splitlines() == [
            f"error: {out}: --rrd and --out name the same file"]
        assert not out.parent.exists() or not list(out.parent.iterdir())


@pytest.mark.parametrize("name, rrd_name", [("r.rrd", "r.rrd.rrd"), ("noext", "noext.rrd"),
                                            ("a.b.mcap", "a.b.rrd")])
def test_default_rrd_never_collides_with_out(session, tmp_path, name, rrd_name):
    folder, _, _ = session
    out = tmp_path / "o" / name
    res = run(["ingest", str(folder), "--out", str(out)])
    assert res.exit_code == 0, (res.output, res.stderr, res.exception)
    assert sorted(p.name for p in out.parent.iterdir()) == sorted([name, rrd_name])
    assert read_raw_mcap(out).markers.frames == FRAMES
    assert "Points3D" in rrd_entities(out.parent / rrd_name)["/mocap/phantom/P00"]


def test_output_over_an_input_is_refused(session):
    folder, _, _ = session
    before = folder_hash(folder)
    res = run(["ingest", str(folder), "--out", str(folder / "force.csv"), "--no-rrd"])
    assert res.exit_code == 2 and "overwrite an input" in res.stderr
    assert folder_hash(folder) == before


def test_phantom_twin_session(tmp_path):
    """A whole synthetic session (6D bodies, pivot, trigger) survives ingest bit for bit."""
    twin = pytest.importorskip("sim.twin.synth_stage")
    from ingest.detect import read_mocap
    from ingest.qtm_6d import read_qtm_6d

    folder = twin.run_synth(None, tmp_path / "twin",
                            twin.SynthParams(seed=1, locations=1, repeats=1))
    out = tmp_path / "twin.mcap"
    res = run(["ingest", str(folder), "--out", str(out), "--no-rrd"])
    assert res.exit_code == 0, res.stderr
    s = read_raw_mcap(out)
    cfg = (folder / "session.toml").read_text()
    mocap = read_mocap(folder / "indentation.tsv")
    assert s.markers.labels == mocap.labels and len(s.phantom_markers) == 25
    assert np.array_equal(s.markers.positions, mocap.positions, equal_nan=True)
    assert np.array_equal(s.markers.time_ns, mocap.time_ns)
    assert s.markers.events == mocap.events and s.trigger_event == "Trigger"
    bodies = read_qtm_6d(folder / "indentation_6D.tsv")
    assert s.bodies.bodies == ["Indenter"] and 'indenter_body = "Indenter"' in cfg
    assert np.array_equal(s.bodies.rotations, bodies.rotations, equal_nan=True)
    assert s.pivot is not None and s.pivot.labels == s.indenter_markers
    assert s.force.trigger is not None and s.calibration is not None

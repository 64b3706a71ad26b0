"""`pipeline inspect`: summaries of the real lab samples and of the files the pipeline writes."""

from __future__ import annotations

import json
import shutil
from pathlib import Path

import h5py
import numpy as np
import pytest
from click.testing import CliRunner
from helpers.paths import REAL_SAMPLES

from ingest.inspect_stage import KEYS, run_inspect
from pipeline.cli import cli

pytestmark = pytest.mark.usefixtures("real_samples")

REAL = REAL_SAMPLES
QTM2010 = REAL / "qtm" / "qtm2010_3d_noheader_nan_gaps.tsv"
QTM2026 = REAL / "qtm" / "qtm2026_3d_15markers_100hz.tsv"
QTM6D = REAL / "qtm" / "qtm2010_6d_3bodies.tsv"
C3D = REAL / "c3d" / "qualisys_55markers_200hz.c3d"
CAL = REAL / "ati" / "nano17_FT14048_SI-50-0.5.cal"


def inspect_json(path: Path) -> dict:
    res = CliRunner().invoke(cli, ["inspect", str(path), "--json"])
    assert res.exit_code == 0, res.stderr
    summary = json.loads(res.output)
    assert tuple(summary) == KEYS                     # the documented keys, always all there
    return summary


@pytest.mark.parametrize("path,fmt,frames,rate,names,missing,first", [
    (QTM2010, "qtm_tsv_3d", 904, 256.0, 14, 7, "Hip"),
    (QTM2026, "qtm_tsv_3d", 2000, 100.0, 15, 0, "New 0000"),
    (C3D, "c3d", 340, 200.0, 55, None, None),
])
def test_marker_exports(path, fmt, frames, rate, names, missing, first):
    s = inspect_json(path)
    assert s["format"] == fmt and s["frames"] == frames and s["rate_hz"] == rate
    assert len(s["markers"]) == names and len(set(s["markers"])) == names
    assert s["duration_s"] == pytest.approx(frames / rate)
    assert s["units"]["position"] == "mm"
    if first:
        assert s["markers"][0] == first
    if missing is not None:
        assert s["missing_samples"] == missing
    assert s["schema"] is None and s["provenance"] is None


def test_qtm2010_names_with_spaces_and_dashes():
    s = run_inspect(QTM2010)
    assert "Knee Hinge" in s["markers"] and "Lower Leg IMU - 3" in s["markers"]


def test_c3d_missing_samples(tmp_path):
    """A C3D with 17 samples whose residual is negative (ezc3d's mark of a gap)."""
    import ezc3d

    rng = np.random.default_rng(3)
    res = np.ones((1, 6, 50))
    res[0, rng.choice(6 * 50, 17, replace=False) // 50, np.arange(17) * 2] = -1.0
    c = ezc3d.c3d()
    c["parameters"]["POINT"]["RATE"]["value"] = [500]
    c["parameters"]["POINT"]["LABELS"]["value"] = [f"P{i}" for i in range(6)]
    c["parameters"]["POINT"]["UNITS"]["value"] = ["mm"]
    c["data"]["points"] = np.vstack([rng.normal(0, 100, (3, 6, 50)), np.ones((1, 6, 50))])
    c["data"]["meta_points"] = {"residuals": res, "camera_masks": np.zeros((7, 6, 50), bool)}
    path = tmp_path / "gaps.c3d"
    c.write(str(path))
    s = inspect_json(path)
    assert s["format"] == "c3d" and s["frames"] == 50 and s["missing_samples"] == 17


def test_6d_export():
    s = inspect_json(QTM6D)
    assert s["format"] == "qtm_tsv_6d" and s["frames"] == 904 and s["rate_hz"] == 256.0
    assert s["bodies"] == ["Upper Leg IMU", "Foot IMU", "Lower Leg IMU"]
    # lost body = residual -1: count independently from the text (16 values + a separator)
    lost = 0
    for line in QTM6D.read_text().splitlines()[11:]:
        cells = line.split("\t")
        lost += sum(float(cells[b * 17 + 6]) < 0 for b in range(3))
    assert s["missing_samples"] == lost > 0


def test_ati_calibration():
    s = inspect_json(CAL)
    assert s["format"] == "ati_cal" and s["frames"] is None
    c = s["calibration"]
    assert (c["serial"], c["body_style"], c["calibration"]) == ("FT14048", "Nano17", "SI-50-0.5")
    assert c["matrix_shape"] == [6, 6]
    assert c["matrix"][0] == pytest.approx([-0.00280, -0.06682, 0.31523, -6.83852, -0.23752,
                                            6.63100])
    assert s["units"] == {"force": "N", "torque": "N-mm"}


@pytest.mark.parametrize("trigger", [None, "trigger", "Sync"])
def test_force_log(tmp_path, trigger):
    path = tmp_path / "force.csv"
    t = np.arange(3000) / 1000
    pulse = [f",{int(i % 1000 < 5)}" if trigger else "" for i in range(3000)]
    rows = ["time,G0,G1,G2,G3,G4,G5" + (f",{trigger}" if trigger else "")] + [
        ",".join([f"{x:.3f}"] + ["0.125"] * 6) + p for x, p in zip(t, pulse, strict=True)]
    path.write_text("\n".join(rows) + "\n")
    s = inspect_json(path)
    assert s["format"] == "force_csv" and s["frames"] == 3000
    assert s["rate_hz"] == pytest.approx(1000.0) and s["duration_s"] == pytest.approx(3.0)
    assert s["channels"] == [f"G{i}" for i in range(6)]          # the trigger is no channel
    assert s["details"].get("trigger_column") == trigger
    assert s["units"] == {f"G{i}": "V" for i in range(6)}
    assert s["missing_samples"] is None                  # a force log is read only when whole


def test_force_log_with_a_gap_is_bad_input(tmp_path):
    path = tmp_path / "force.csv"
    path.write_text("time,G0\n0.000,0.125\n0.001,nan\n0.002,0.250\n")
    res = CliRunner().invoke(cli, ["inspect", str(path)])
    assert res.exit_code == 2
    assert res.stderr.strip().splitlines() == [
        f"error: {path}:line 3: column G0 has no value (or an infinite one)"]


@pytest.mark.parametrize("version", ["7", "7.3"])
def test_qtm_mat(tmp_path, version):
    from core.series import MarkerSeries
    from ingest.qtm_mat import write_qtm_mat

    pos = np.random.default_rng(0).normal(0, 0.1, (300, 4, 3))
    pos[20:30, 1] = np.nan
    m = MarkerSeries("x", np.arange(300, dtype=np.int64) * 5_000_000, ["a", "b c", "d", "e"],
                     pos, 200.0)
    path = tmp_path / "trial.mat"
    write_qtm_mat(path, m, version)
    s = inspect_json(path)
    assert s["format"] == "qtm_mat" and s["frames"] == 300 and s["rate_hz"] == 200.0
    assert s["markers"] == ["a", "b c", "d", "e"] and s["missing_samples"] == 10


@pytest.mark.parametrize("kind", ["parquet", "mat"])
def test_force_log_parquet_and_mat(tmp_path, kind):
    import pandas as pd
    import scipy.io

    names = ["Fx", "Fy", "Fz", "Tx", "Ty", "Tz"]
    cols = {"t": np.arange(2000) / 1000, **{n: np.full(2000, 0.5) for n in names}}
    path = tmp_path / f"force.{kind}"
    if kind == "parquet":
        pd.DataFrame(cols).to_parquet(path)
    else:
        scipy.io.savemat(path, cols)
    s = inspect_json(path)
    assert s["format"] == f"force_{kind}" and s["frames"] == 2000
    assert s["rate_hz"] == pytest.approx(1000.0) and s["channels"] == names
    assert s["details"]["time_column"] == "t" and s["details"]["kind"] == "wrench"
    assert s["units"] == {"Fx": "N", "Fy": "N", "Fz": "N", "Tx": "N*m", "Ty": "N*m", "Tz": "N*m"}


@pytest.fixture(scope="module")
def ingested(tmp_path_factory) -> tuple[Path, Path]:
    """`pipeline ingest` of a folder made of the real 2026 TSV, the real .cal and a force CSV."""
    folder = tmp_path_factory.mktemp("session")
    shutil.copy(QTM2026, folder / "trial.tsv")
    shutil.copy(CAL, folder / "ft.cal")
    t = np.arange(20_000) / 1000
    rows = ["time,a,b,c,d,e,f"] + [",".join([f"{x:.3f}"] + [f"{np.sin(x + k):.5f}"
                                                          for k in range(6)]) for x in t]
    (folder / "force.csv").write_text("\n".join(rows) + "\n")
    names = [f"New {i:04d}" for i in (0, *range(2, 16))]
    (folder / "session.toml").write_text(
        'name = "real-2026"\n[mocap]\nfile = "trial.tsv"\n'
        f"phantom_markers = {json.dumps(names[:10])}\nindenter_markers = "
        f"{json.dumps(names[10:14])}\n[force]\nfile = \"force.csv\"\n"
        'channels = ["a", "b", "c", "d", "e", "f"]\ncalibration = "ft.cal"\n'
        "[phantom]\nrows = 2\n")                        # 10 markers: 2 rows of 5
    out = folder.parent / "real.mcap"
    res = CliRunner().invoke(cli, ["-q", "ingest", str(folder), "--out", str(out)])
    assert res.exit_code == 0, res.stderr
    return out, out.with_suffix(".rrd")


def test_raw_mcap(ingested):
    s = inspect_json(ingested[0])
    assert s["format"] == "mcap" and s["schema"] == "phantom.raw_mcap"
    assert s["schema_version"] == "1.0"
    assert s["frames"] == 2000 and s["rate_hz"] == 100.0 and len(s["markers"]) == 15
    assert s["missing_samples"] == 0 and s["duration_s"] == pytest.approx(20.0)
    assert s["channels"] == ["a", "b", "c", "d", "e", "f"]
    assert s["streams"]["/force/raw"]["frames"] == 20_000
    assert s["streams"]["/mocap/markers"]["names"] == s["markers"]
    assert s["provenance"]["stage"] == "ingest"
    assert {Path(p).name for p in s["provenance"]["inputs"]} == \
        {"session.toml", "trial.tsv", "force.csv", "ft.cal"}
    assert s["calibration"]["serial"] == "FT14048"
    text = CliRunner().invoke(cli, ["inspect", str(ingested[0])]).output
    assert "frames:      2000 at 100 Hz" in text and "phantom.raw_mcap 1.0" in text
    assert "provenance:  stage ingest" in text


def test_recording(ingested):
    s = inspect_json(ingested[1])
    assert s["format"] == "rrd" and s["details"]["blueprint"] is True
    assert {e for e in s["entities"] if e.startswith("/force/")} == \
        {f"/force/V/{c}" for c in "abcdef"}
    assert all("Scalars" in s["entities"][f"/force/V/{c}"] for c in "abcdef")
    assert "Points3D" in s["entities"]["/mocap/phantom/New_0000"]


def test_hdf5_generic(tmp_path):
    path = tmp_path / "x.h5"
    pts = np.zeros((100, 26, 3))
    pts[[3, 3, 50], [0, 1, 25]] = np.nan
    prov = {"stage": "sync", "inputs": {"a.mcap": "ab" * 32}}
    with h5py.File(path, "w") as f:
        f.attrs.update(schema="phantom.synced", schema_version="1.0",
                       provenance=json.dumps(prov))
        f["time_ns"] = np.arange(100, dtype=np.int64) * 2_000_000
        f["time_ns"].attrs["units"] = "ns"
        f["points"] = pts
        f["points"].attrs["units"] = "m"
        f.create_group("force")["magnitude"] = np.ones(100)
    s = inspect_json(path)
    assert s["format"] == "hdf5" and s["schema"] == "phantom.synced"
    assert s["schema_version"] == "1.0" and s["provenance"] == prov
    assert s["frames"] == 100 and s["rate_hz"] == pytest.approx(500.0)
    assert s["missing_samples"] == 3
    assert s["datasets"]["points"] == {"shape": [100, 26, 3], "dtype": "float64", "units": "m"}
    assert s["datasets"]["force/magnitude"]["units"] is None


def test_json_manifest(tmp_path):
    path = tmp_path / "splits.json"
    role = lambda g: {"groups": g, "single": [], "multi": []}  # noqa: E731
    doc = {"schema": "phantom.folds", "schema_version": "2.0", "folds": [
        {"train": role([1, 2, 3]), "val": role([4]), "test": role([5])}]}
    path.write_text(json.dumps(doc))
    s = inspect_json(path)
    assert s["format"] == "json" and s["schema"] == "phantom.folds"
    assert s["details"]["folds"] == [{"train": 3, "val": 1, "test": 1}]
    assert "invalid" in s["details"]["valid"]          # no data, ratio, seed...


def test_json_documents_are_known_by_their_schema_name(tmp_path):
    """A metrics document is checked as one whatever its file is called; a document of another
    schema with the same tables is not taken for one; one with no schema but the metrics
    tables is a metrics document older than 1.0, and its check says so."""
    tables = {"schema_version": "1.1", "runs": [], "overall": [], "provenance": {}}
    renamed = tmp_path / "other.json"
    renamed.write_text(json.dumps({"schema": "phantom.metrics", **tables}))
    s = inspect_json(renamed)
    assert s["schema"] == "phantom.metrics" and s["details"]["valid"] == "valid"
    foreign = tmp_path / "metrics.json"
    foreign.write_text(json.dumps({"schema": "lab.metrics", **tables}))
    s = inspect_json(foreign)
    assert s["schema"] == "lab.metrics" and "valid" not in s["details"]
    old = tmp_path / "old.json"
    old.write_text(json.dumps({k: v for k, v in tables.items() if k != "schema_version"}))
    assert "before phantom.metrics 1.0" in inspect_json(old)["details"]["valid"]


def test_unknown_file_is_bad_input(tmp_path):
    path = tmp_path / "blob.bin"
    path.write_bytes(bytes(range(256)) * 4)
    res = CliRunner().invoke(cli, ["inspect", str(path)])
    assert res.exit_code == 2
    assert res.stderr.strip().splitlines() == [f"error: {path}: unknown format"]


def test_text_summary_is_readable():
    res = CliRunner().invoke(cli, ["inspect", str(QTM2010)])
    assert res.exit_code == 0
    assert "format:      qtm_tsv_3d" in res.output
    assert "frames:      904 at 256 Hz (3.531 s)" in res.output
    assert "missing:     7 samples" in res.output


def test_inspect_session_toml(tmp_path):
    """A session.toml summary names its markers, channels and files."""
    import json as _json

    from click.testing import CliRunner

    from pipeline.cli import cli
    from sim.twin.synth_params import SynthParams
    from sim.twin.synth_stage import run_synth

    folder = run_synth(None, tmp_path / "s", SynthParams(seed=3, locations=1, repeats=1,
                                                         press_seconds=3.0, pivot_seconds=3.0))
    res = CliRunner().invoke(cli, ["inspect", str(folder / "session.toml"), "--json"])
    assert res.exit_code == 0, res.output
    s = _json.loads(res.output)
    assert s["format"] == "session_toml" and s["schema"] == "phantom.session"
    assert len(s["markers"]) == 29 and s["details"]["phantom_markers"] == 25
    assert s["details"]["files"]["pivot"] == "pivot.tsv"

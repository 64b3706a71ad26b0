"""QTM TSV 6D exports (`ingest/qtm_6d.py`): a real export checked against its raw text and
its own Euler angles, the newer and label-less layouts, a row that fits no layout."""

from __future__ import annotations

import numpy as np
import pytest
from helpers.qtm_files import OLD_6D, qtm_header, raw_rows, refused, write_tsv

from core.series import BodySeries
from ingest.qtm_6d import read_qtm_6d
from ingest.qtm_motion import read_qtm_tsv

pytestmark = pytest.mark.usefixtures("real_samples")


def test_old_6d_export_bodies_rotations_and_lost_frames():
    s = read_qtm_6d(OLD_6D)
    assert isinstance(s, BodySeries)
    assert s.bodies == ["Upper Leg IMU", "Foot IMU", "Lower Leg IMU"] and s.frames == 904
    rows = raw_rows(OLD_6D, 11)
    lost = sum(r[17 * b + 6] == "-1.00000" for r in rows for b in range(3))
    assert lost == 7 == s.missing_samples()
    assert np.isnan(s.rotations[np.isnan(s.residuals)]).all()
    first = np.array(rows[0][17:33], float)                               # second body, row 0
    assert s.positions[0, 1] == pytest.approx(first[:3] / 1000)
    assert s.residuals[0, 1] == pytest.approx(first[6] / 1000)
    # Rot[0..8] is column-major: check against the file's own Euler angles (label row
    # "Yaw Pitch Roll"), which give R = Rz(yaw) Ry(pitch) Rx(roll) for this export
    yaw, pitch, roll = np.radians(first[3:6])
    c, s_ = np.cos, np.sin
    rz = np.array([[c(yaw), -s_(yaw), 0], [s_(yaw), c(yaw), 0], [0, 0, 1]])
    ry = np.array([[c(pitch), 0, s_(pitch)], [0, 1, 0], [-s_(pitch), 0, c(pitch)]])
    rx = np.array([[1, 0, 0], [0, c(roll), -s_(roll)], [0, s_(roll), c(roll)]])
    assert np.abs(s.rotations[0, 1] - rz @ ry @ rx).max() < 1e-4
    ok = ~np.isnan(s.residuals)
    r = s.rotations[ok]
    assert np.abs(r @ r.transpose(0, 2, 1) - np.eye(3)).max() < 1e-3


def test_new_6d_layout_with_frame_time_and_column_line(tmp_path):
    head = qtm_header(["Indenter", "Plate"], 2, 500, key="BODY_NAMES")
    per = ["X", "Y", "Z", "Roll", "Pitch", "Yaw", "Residual", *(f"Rot[{k}]" for k in range(9))]
    cols = ["Frame", "Time"] + [f"{b} {p}" for b in ("Indenter", "Plate") for p in per]
    rot = [0, 1, 0, -1, 0, 0, 0, 0, 1]                   # columns e_y, -e_x, e_z
    good = ["10", "20", "30", "0", "0", "90", "0.5", *map(str, rot)]
    lost = ["0"] * 6 + ["-1"] + ["0"] * 9
    rows = ["\t".join(["1", "0.000", *good, *lost]), "\t".join(["2", "0.002", *lost, *good])]
    s = read_qtm_tsv(write_tsv(tmp_path, [*head, "\t".join(cols), *rows]))
    assert isinstance(s, BodySeries) and s.bodies == ["Indenter", "Plate"]
    assert s.positions[0, 0] == pytest.approx([0.01, 0.02, 0.03])
    assert s.rotations[0, 0] @ np.array([1, 0, 0]) == pytest.approx([0, 1, 0])
    assert s.residuals[0, 0] == pytest.approx(0.0005)
    assert np.isnan(s.positions[0, 1]).all() and np.isnan(s.rotations[1, 0]).all()
    assert s.missing_samples() == 2 and s.time_ns.tolist() == [0, 2_000_000]


def test_bad_6d_row_that_fits_no_body_layout(tmp_path):
    head = qtm_header(["Indenter"], 1, key="BODY_NAMES")
    refused(write_tsv(tmp_path, [*head, "\t".join(["1"] * 15)]), "does not fit 1 bodies")


def test_6d_frame_time_without_labels_two_bodies(tmp_path):
    body = ["1", "2", "3", "0", "0", "0", "0.4", "1", "0", "0", "0", "1", "0", "0", "0", "1"]
    rows = ["\t".join([str(i + 1), f"{i / 100:.5f}", *body, *body]) for i in range(3)]
    s = read_qtm_6d(write_tsv(tmp_path, [*qtm_header(["A", "B"], 3, 100, key="BODY_NAMES"), *rows]))
    assert s.time_ns.tolist() == [0, 10_000_000, 20_000_000]
    assert s.positions[2, 1] == pytest.approx([0.001, 0.002, 0.003])
    assert np.array_equal(s.rotations[0, 0], np.eye(3)) and s.missing_samples() == 0

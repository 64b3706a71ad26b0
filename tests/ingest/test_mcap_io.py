"""The raw-session MCAP: bit-exact round trip, the documented block layout, damage detection."""

from __future__ import annotations

import json
import struct

import numpy as np
import pytest
from mcap.reader import make_reader
from mcap.writer import Writer

from core.errors import BadInput
from core.series import AtiCalibration, BodySeries, ForceSeries, MarkerSeries, RawSession
from data_schema.raw_mcap import BLOCK_HEADER, RAW_MCAP, validate_raw_mcap
from ingest.ingest_params import IngestParams
from ingest.mcap_io import read_raw_mcap, write_raw_mcap

PROV = {"stage": "ingest", "code_version": "test", "inputs": {"a.tsv": "0" * 64}}
COMPRESSION = IngestParams().compression      # ingest's default


def make_session(frames: int = 1234, gauge: bool = True, extras: bool = True) -> RawSession:
    """A session with every optional stream, gaps, events and odd (negative, offset) times."""
    rng = np.random.default_rng(7)
    labels = [f"P{i:02d}" for i in range(25)] + ["I1", "I2", "I3", "I4", "extra marker"]
    t = 3_000_000_000 + np.arange(frames, dtype=np.int64) * 2_000_000 + rng.integers(0, 9, frames)
    pos = rng.normal(0.0, 0.05, (frames, len(labels), 3))
    pos[10:40, 3] = np.nan                         # an occlusion gap
    pos[frames - 1, 27] = np.nan                   # a gap in the last frame
    res = rng.uniform(0, 1e-3, (frames, len(labels)))
    res[np.isnan(pos).any(axis=2)] = np.nan
    markers = MarkerSeries("trial.tsv", t, labels, pos, 500.0, residuals=res if extras else None,
                           events=[("Trigger", int(t[5])), ("Trigger", int(t[frames // 2]))],
                           meta={"TIME_STAMP": "2026-01-19, 10:19:43.755", "cameras": 10})
    nf = frames * 2 + 1
    ft = -5_000_000 + np.arange(nf, dtype=np.int64) * 1_000_000     # starts before 0
    force = ForceSeries(
        "force.csv", ft, [f"G{i}" for i in range(6)] if gauge else
        ["Fx", "Fy", "Fz", "Tx", "Ty", "Tz"], rng.normal(0, 1, (nf, 6)),
        ["V"] * 6 if gauge else ["N", "N", "N", "N*m", "N*m", "N*m"],
        "gauge" if gauge else "wrench", 1000.0,
        trigger=(rng.uniform(size=nf) > 0.99).astype(float) if extras else None,
    )
    cal = AtiCalibration("ft.cal", "FT14048", "Nano17", "SI-12-0.12", rng.normal(size=(6, 6)),
                         np.array([12, 12, 17, 0.12, 0.12, 0.12]), "N", "N-mm") if gauge else None
    bodies = pivot = None
    if extras:
        rot = np.tile(np.eye(3), (frames, 1, 1, 1))
        bp = rng.normal(size=(frames, 1, 3))
        bp[50:60] = np.nan
        rot[50:60] = np.nan
        bodies = BodySeries("trial_6d.tsv", t, ["Indenter"], bp, rot,
                            rng.uniform(size=(frames, 1)), 500.0)
        pt = np.arange(700, dtype=np.int64) * 2_000_000
        pivot = MarkerSeries("pivot.tsv", pt, ["I1", "I2", "I3", "I4"],
                             rng.normal(size=(700, 4, 3)), 500.0)
    return RawSession("phantom-test", markers, force, labels[:25], ["I1", "I2", "I3", "I4"],
                      calibration=cal, bodies=bodies, pivot=pivot,
                      trigger_event="Trigger" if extras else None)


def same(a: np.ndarray, b: np.ndarray) -> bool:
    """Bit-identical values, NaN where the other has NaN."""
    return a.shape == b.shape and np.array_equal(a, b, equal_nan=True)


@pytest.mark.parametrize("gauge,extras,compression", [(True, True, "none"),
                                                       (False, False, "none"),
                                                       (True, True, "zstd")])
def test_round_trip_is_exact(tmp_path, gauge, extras, compression):
    s = make_session(gauge=gauge, extras=extras)
    path = tmp_path / "s.mcap"
    write_raw_mcap(path, s, {"provenance": PROV}, compression)
    validate_raw_mcap(path)
    r = read_raw_mcap(path)
    assert r.name == s.name and r.provenance == PROV
    assert r.phantom_markers == s.phantom_markers and r.indenter_markers == s.indenter_markers
    assert r.trigger_event == s.trigger_event
    m, rm = s.markers, r.markers
    assert rm.labels == m.labels and rm.rate_hz == 500.0 and rm.source == "trial.tsv"
    assert same(rm.time_ns, m.time_ns) and rm.time_ns.dtype == np.int64
    assert same(rm.positions, m.positions)
    assert np.isnan(rm.positions[10:40, 3]).all() and rm.missing_samples() == m.missing_samples()
    assert rm.events == m.events and rm.meta == m.meta
    assert (rm.residuals is None) == (m.residuals is None)
    f, rf = s.force, r.force
    assert rf.channels == f.channels and rf.units == f.units and rf.kind == f.kind
    assert same(rf.time_ns, f.time_ns) and same(rf.values, f.values)
    if extras:
        assert same(rm.residuals, m.residuals) and same(rf.trigger, f.trigger)
        assert r.bodies.bodies == ["Indenter"]
        for a in ("time_ns", "positions", "rotations", "residuals"):
            assert same(getattr(r.bodies, a), getattr(s.bodies, a)), a
        assert same(r.pivot.positions, s.pivot.positions) and r.pivot.labels == s.pivot.labels
    else:
        assert r.bodies is None and r.pivot is None and rf.trigger is None
    if gauge:
        assert same(r.calibration.matrix, s.calibration.matrix)
        assert r.calibration.serial == "FT14048" and r.calibration.torque_units == "N-mm"
    else:
        assert r.calibration is None


def test_block_layout_matches_the_documentation(tmp_path):
    """Decode the file with the MCAP library and struct alone, as the schema doc describes."""
    s = make_session(frames=1234)
    path = tmp_path / "s.mcap"
    write_raw_mcap(path, s, {"provenance": PROV}, COMPRESSION)
    with open(path, "rb") as fh:
        reader = make_reader(fh)
        summary = reader.get_summary()
        assert {c.compression for c in summary.chunk_indexes} == {""}    # uncompressed
        records = {m.name: m.metadata for m in reader.iter_metadata()}
        got: dict[str, list[tuple[int, int, bytes]]] = {}
        for schema, ch, msg in reader.iter_messages():
            assert ch.message_encoding == "phantom.block" and schema.encoding == "phantom.block"
            assert schema.name == RAW_MCAP.channel(ch.topic).schema_name
            got.setdefault(ch.topic, []).append((msg.sequence, msg.log_time, msg.data))
            if ch.topic == "/mocap/markers":
                meta = ch.metadata
    assert set(records) == {"session", "calibration", "provenance"}
    assert json.loads(records["session"]["mocap"])["names"] == s.markers.labels
    assert json.loads(records["calibration"]["matrix"]) == s.calibration.matrix.tolist()
    assert json.loads(meta["names"]) == s.markers.labels and meta["block_samples"] == "500"
    assert sorted(got) == ["/force/raw", "/force/trigger", "/mocap/bodies", "/mocap/markers",
                           "/mocap/residuals", "/pivot/markers"]
    blocks = sorted(got["/mocap/markers"])
    assert [b[0] for b in blocks] == [0, 1, 2]                  # 1234 frames: 500, 500, 234
    seq, log_time, data = blocks[1]
    magic, version, flags, n, k = struct.unpack_from("<4sHHII", data)
    assert (magic, version, flags, n, k) == (b"PBLK", 1, 0, 500, 30 * 3)
    times = struct.unpack_from(f"<{n}q", data, 16)
    values = struct.unpack_from(f"<{n * k}d", data, 16 + 8 * n)
    assert list(times) == s.markers.time_ns[500:1000].tolist() and log_time == times[0]
    np.testing.assert_array_equal(np.reshape(values, (n, 30, 3)), s.markers.positions[500:1000])
    assert len(data) == BLOCK_HEADER.size + 8 * n * (1 + k)
    # the force log starts at -5 ms: log_time is clipped at 0, the block keeps the exact time
    first = sorted(got["/force/raw"])[0]
    assert first[1] == 0 and struct.unpack_from("<q", first[2], 16)[0] == -5_000_000


def test_rerun_reads_the_file(tmp_path):
    from rerun.chunk import McapReader

    path = tmp_path / "s.mcap"
    write_raw_mcap(path, make_session(), {"provenance": PROV}, COMPRESSION)
    reader = McapReader(path)
    assert sum(1 for _ in reader.stream()) > 0
    info = reader.info()
    assert {c.topic for c in info.channels} >= {"/mocap/markers", "/force/raw"}
    assert info.metadata_count == 3


@pytest.fixture(params=["none", "zstd"])
def written(tmp_path, request):
    path = tmp_path / "s.mcap"
    write_raw_mcap(path, make_session(frames=3000), {"provenance": PROV}, request.param)
    return path


@pytest.mark.parametrize("cut", [0.5, 0.97, 0.9999])
def test_truncated_file_is_bad_input(written, cut):
    data = written.read_bytes()
    written.write_bytes(data[: int(len(data) * cut)])
    for fn in (read_raw_mcap, validate_raw_mcap):
        with pytest.raises(BadInput) as e:
            fn(written)
        assert str(written) in e.value.line()


def test_corrupted_chunk_is_bad_input(written):
    with open(written, "rb") as fh:
        chunk = make_reader(fh).get_summary().chunk_indexes[1]
    data = bytearray(written.read_bytes())
    middle = chunk.chunk_start_offset + chunk.chunk_length // 2
    data[middle:middle + 8] = bytes(255 - b for b in data[middle:middle + 8])
    written.write_bytes(bytes(data))
    for fn in (read_raw_mcap, validate_raw_mcap):
        with pytest.raises(BadInput):
            fn(written)


def test_other_files_are_bad_input(tmp_path):
    text = tmp_path / "notes.mcap"
    text.write_text("hello, not an mcap file\n" * 10)
    with pytest.raises(BadInput, match="not an MCAP file"):
        read_raw_mcap(text)
    foreign = tmp_path / "foreign.mcap"                  # a valid MCAP, but not our layout
    with open(foreign, "wb") as fh:
        w = Writer(fh)
        w.start()
        sid = w.register_schema("x", "jsonschema", b"{}")
        cid = w.register_channel("/x", "json", sid)
        w.add_message(cid, 0, b"{}", 0)
        w.finish()
    with pytest.raises(BadInput, match="missing metadata record 'session'"):
        validate_raw_mcap(foreign)


@pytest.mark.parametrize("damage", ["no events", "no source", "events not a list"])
def test_session_record_lacking_a_key_is_bad_input(tmp_path, damage):
    """The top-level keys are checked by the layout; a nested one is caught when read."""
    from ingest.mcap_io import _session_record

    s = make_session(frames=100, extras=False)
    record = _session_record(s)
    if damage == "no events":
        del record["mocap"]["events"]
    elif damage == "no source":
        del record["force"]["source"]
    else:
        record["mocap"]["events"] = 5
    path = tmp_path / "s.mcap"
    write_raw_mcap(path, s, {"provenance": PROV, "session": record}, COMPRESSION)
    with pytest.raises(BadInput, match="not a readable raw MCAP file") as e:
        read_raw_mcap(path)
    assert e.value.path == str(path)


def test_decreasing_time_is_refused_on_write(tmp_path):
    s = make_session(frames=100, extras=False)
    s.force.time_ns[50] = s.force.time_ns[49]
    with pytest.raises(BadInput, match="not increasing"):
        write_raw_mcap(tmp_path / "s.mcap", s, {"provenance": PROV}, COMPRESSION)
    assert not list(tmp_path.iterdir())

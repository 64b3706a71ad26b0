"""The pieces every stage stands on: atomic outputs, bad-input lines, schemas, session.toml, CLI."""

from __future__ import annotations

import json
from pathlib import Path

import click
import h5py
import numpy as np
import pytest
from click.testing import CliRunner

from core.atomic import atomic_output, atomic_outputs
from core.errors import BadInput
from core.provenance import make_provenance, sha256_file
from core.recording import default_rrd_path
from data_schema import Dataset, H5Schema, validate_h5
from data_schema.session import read_session
from pipeline.cli import COMMANDS, cli
from pipeline.options import resolve_rrd


def test_atomic_output_renames_only_on_success(tmp_path):
    out = tmp_path / "sub" / "a.h5"
    with atomic_output(out) as tmp:
        tmp.write_text("done")
        assert not out.exists()
    assert out.read_text() == "done"
    with pytest.raises(RuntimeError), atomic_outputs(tmp_path / "b", None, tmp_path / "c") as tmps:
        assert tmps[1] is None
        tmps[0].write_text("half")
        tmps[2].write_text("half")
        raise RuntimeError("crash")
    assert sorted(p.name for p in tmp_path.iterdir()) == ["sub"]


def test_an_output_refused_by_its_own_check_is_named_as_asked_not_by_its_temporary_name(
        tmp_path):
    out = tmp_path / "states.h5"
    with pytest.raises(BadInput) as e, atomic_output(out) as tmp:
        tmp.write_text("bad")
        raise BadInput(tmp, "root attribute footprint_m is wrong", "line 3")
    assert e.value.line() == f"{out}:line 3: root attribute footprint_m is wrong"
    assert not list(tmp_path.iterdir())


def test_atomic_outputs_refuse_one_path_twice(tmp_path):
    a = tmp_path / "o" / "a.mcap"
    for twice in (a, tmp_path / "o" / ".." / "o" / "a.mcap"):
        with pytest.raises(ValueError, match="named twice"), atomic_outputs(a, None, twice):
            pass
    assert not list(tmp_path.iterdir())


def test_atomic_output_under_a_file_is_bad_input(tmp_path):
    (tmp_path / "f").write_text("x")
    with pytest.raises(BadInput, match="a file is in the way"), \
            atomic_output(tmp_path / "f" / "a.h5"):
        pass
    assert (tmp_path / "f").read_text() == "x"


@pytest.mark.parametrize("out, rrd", [("o/x.mcap", "o/x.rrd"), ("o/a.b.h5", "o/a.b.rrd"),
                                      ("o/r.rrd", "o/r.rrd.rrd"), ("o/noext", "o/noext.rrd")])
def test_default_rrd_path_never_equals_the_output(tmp_path, out, rrd):
    assert default_rrd_path(tmp_path / out) == tmp_path / rrd
    assert default_rrd_path(tmp_path / out, folder=True) == tmp_path / out / "recording.rrd"
    assert resolve_rrd(tmp_path / out, None, False) == tmp_path / rrd
    assert resolve_rrd(tmp_path / out, None, True) is None


def test_default_rrd_path_of_a_folder(tmp_path):
    assert default_rrd_path(tmp_path) == tmp_path / "recording.rrd"        # an existing folder

    @click.command()
    @click.argument("out_dir", type=click.Path(file_okay=False, path_type=Path))
    def make(out_dir: Path) -> None:
        """A command whose output is a (new) folder, as synth's OUT_DIR."""
        click.echo(resolve_rrd(out_dir, None, False))

    res = CliRunner().invoke(make, [str(tmp_path / "new.v1")])
    assert res.output.strip() == str(tmp_path / "new.v1" / "recording.rrd")


def test_resolve_rrd_refuses_the_output_itself(tmp_path):
    out = tmp_path / "x.mcap"
    for rrd in (out, tmp_path / "." / "x.mcap"):
        with pytest.raises(BadInput, match="--rrd and --out name the same file"):
            resolve_rrd(out, rrd, False)


def test_bad_input_line_names_file_and_place():
    e = BadInput("x/trial.tsv", "time is not increasing", where="line 12")
    assert str(e) == "x/trial.tsv:line 12: time is not increasing"


def test_provenance_hashes_inputs(tmp_path):
    f = tmp_path / "in.txt"
    f.write_bytes(b"abc")
    p = make_provenance("test", {"k": 1, "path": tmp_path}, [f], "s", "1.0")
    assert p["inputs"][str(f)] == sha256_file(f)
    assert p["inputs"][str(f)].startswith("ba7816bf")  # sha256("abc")
    json.dumps(p)


SCHEMA = H5Schema(
    name="test.schema", version="1.2",
    datasets=(
        Dataset("a/x", "f4", ("S", 3), "m"),
        Dataset("a/y", "i4", ("S",)),
        Dataset("p/*/t", "i8", ("T",), "ns"),
        Dataset("p/*/v", "f8", ("T", 2), "N"),
    ),
)


def _write(path, s=4, t_sizes=(5, 7), bad=None):
    with h5py.File(path, "w") as f:
        f.attrs["schema"], f.attrs["schema_version"] = "test.schema", "1.0"
        f.attrs["provenance"] = "{}"
        f.create_dataset("a/x", data=np.zeros((s, 3), "f4")).attrs["units"] = "m"
        f.create_dataset("a/y", data=np.zeros(s + (bad == "shape"), "i4"))
        for i, t in enumerate(t_sizes):
            f.create_dataset(f"p/{i}/t", data=np.zeros(t, "i8")).attrs["units"] = "ns"
            v = f.create_dataset(f"p/{i}/v", data=np.zeros((t, 2), "f8"))
            v.attrs["units"] = "mm" if bad == "units" else "N"
        if bad == "attr":
            del f.attrs["provenance"]


@pytest.mark.parametrize("bad, words", [("shape", "S=5"), ("units", "units"),
                                        ("attr", "provenance")])
def test_validator_finds_departures(tmp_path, bad, words):
    good = tmp_path / "good.h5"
    _write(good)
    validate_h5(good, SCHEMA)  # named sizes bind per press: T=5 and T=7 are both fine
    broken = tmp_path / "bad.h5"
    _write(broken, bad=bad)
    with pytest.raises(BadInput, match=words):
        validate_h5(broken, SCHEMA)


def _session(tmp_path, **over):
    for name in ("t.tsv", "f.csv", "s.cal"):
        (tmp_path / name).write_text("x")
    text = {
        "mocap": 'file = "t.tsv"\nphantom_markers = ["P1", "P2", "P3", "P4"]\n'
                 'indenter_markers = ["I1"]',
        "force": 'file = "f.csv"\nchannels = ["a","b","c","d","e","f"]\ncalibration = "s.cal"',
    }
    text.update(over)
    (tmp_path / "session.toml").write_text(
        "".join(f"[{k}]\n{v}\n" for k, v in text.items() if v is not None))
    return tmp_path


def test_session_toml_parses(tmp_path):
    s = read_session(_session(tmp_path))
    assert s.mocap.phantom_markers == ["P1", "P2", "P3", "P4"]
    assert s.force.units == ["V"] * 6 and s.force.time_unit == "s"


@pytest.mark.parametrize("over, words", [
    ({"mocap": 'file = "none.tsv"\nphantom_markers = ["P"]\nindenter_markers = ["I"]'},
     "no such file"),
    ({"mocap": 'file = "t.tsv"\nphantom_markers = ["P", "P"]\nindenter_markers = ["I"]'},
     "duplicate"),
    ({"force": 'file = "f.csv"\nchannels = ["a","b","c","d","e","f"]'}, "calibration"),
    ({"force": None}, r"\[force\]"),
    ({"mocap": 'file = "t.tsv"\nphantom_markers = ["P"]\nindenter_markers = ["I"]\n'
               'trigger_event = 7'}, "mocap.trigger_event must be a non-empty string"),
    ({"force": 'file = "f.csv"\nchannels = ["a","b","c","d","e","f"]\ncalibration = "s.cal"\n'
               "units = 5"}, "force.units: units must be a unit or a list"),
    ({"force": 'file = "f.csv"\nchannels = ["a","b","c","d","e","f"]\ncalibration = "s.cal"\n'
               'units = "mm"'}, "unknown unit 'mm'"),
    ({"force": 'file = "f.csv"\nchannels = ["a","b","c","d","e","f"]\ncalibration = "s.cal"\n'
               'units = "N"'}, "does not fit kind 'gauge'"),
    ({"force": 'file = "f.csv"\nchannels = ["a","b","c","d","e","f"]\ncalibration = "s.cal"\n'
               'time_unit = ["s"]'}, "force.time_unit must be a non-empty string"),
    ({"force": 'file = "f.csv"\nchannels = ["a","b","c","d","e","f"]\ncalibration = "s.cal"\n'
               "trigger_column = 3.5"}, "force.trigger_column must name channels by name"),
    ({"force": 'file = "f.csv"\nchannels = ["a","b","c","d","e",0]\ncalibration = "s.cal"'},
     "force.channels must name channels by name .* or number .*got 0"),
    ({"force": 'file = "f.csv"\nchannels = ["a","b","c","d","e","f"]\ncalibration = "s.cal"\n'
               "rate_hz = -1"}, "force.rate_hz must be a rate in Hz"),
    ({"force": 'file = "f.csv"\nchannels = ["a","b","c","d","e","f"]\ncalibration = 5'},
     "force.calibration must be a non-empty string"),
    ({"pivot": 'file = ""'}, "pivot.file must be a non-empty string"),
])
def test_session_toml_errors(tmp_path, over, words):
    with pytest.raises(BadInput, match=words):
        read_session(_session(tmp_path, **over))


@pytest.mark.parametrize("top, words", [
    ('pivot = "t.tsv"', "pivot must be a \\[pivot\\] table"),
    ('schema_version = "2.0"', "schema_version '2.0' is not compatible with 1.0"),
    ("schema_version = 1", "schema_version must be a non-empty string"),
    ('schema = "phantom.other"', "schema is 'phantom.other'"),
    ("name = []", "name must be a non-empty string"),
])
def test_session_toml_top_level_errors(tmp_path, top, words):
    folder = _session(tmp_path)
    path = folder / "session.toml"
    path.write_text(top + "\n" + path.read_text())
    with pytest.raises(BadInput, match=words):
        read_session(folder)


def test_session_toml_units_and_pivot(tmp_path):
    folder = _session(tmp_path, force='file = "f.csv"\nchannels = ["a","b","c","d","e","f"]\n'
                                      'kind = "wrench"\nunits = "N, N, N, N-mm, N-mm, N-mm"',
                      pivot='file = "t.tsv"')
    s = read_session(folder)
    assert s.force.units == ["N", "N", "N", "N-mm", "N-mm", "N-mm"] and s.force.calibration is None
    assert s.pivot_file == folder / "t.tsv" and s.force.trigger_column is None


def test_every_command_has_help_that_says_what_it_reads_and_writes():
    runner = CliRunner()
    names = cli.list_commands(click.Context(cli))
    assert names, "no command registered"
    for name in names:
        r = runner.invoke(cli, [name, "--help"])
        assert r.exit_code == 0, (name, r.output)
        text = r.output.lower()
        assert "read" in text and "writ" in text, (name, r.output)
    assert set(names) <= set(COMMANDS)


def test_recordings_of_one_process_have_their_own_ids(tmp_path) -> None:
    """A demo worker writes many recordings: opened together they must not merge into one."""
    import rerun as rr
    from rerun.chunk import RrdReader

    from core.recording import recording

    ids = []
    for name in ("a.rrd", "b.rrd"):
        with recording("phantom-test", tmp_path / name) as rec:
            rec.log("x", rr.Scalars(1.0))
        ids += [e.recording_id for e in RrdReader(str(tmp_path / name)).recordings()]
    assert len(ids) == 2 and ids[0] != ids[1]

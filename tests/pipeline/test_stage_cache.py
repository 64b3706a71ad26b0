"""A stage is skipped only when its inputs, arguments, code and outputs are what its stamp says."""

from __future__ import annotations

from pipeline.stage_cache import is_fresh, stamp_path, write_stamp


def _stage(tmp_path):
    src = tmp_path / "in"
    src.mkdir()
    (src / "a.txt").write_text("a")
    out = tmp_path / "out.h5"
    out.write_text("result")
    return src, out


def test_fresh_only_after_a_stamped_run(tmp_path):
    src, out = _stage(tmp_path)
    args = ["sync", "x", "--out", str(out)]
    assert not is_fresh(args, [src], [out])
    write_stamp(args, [src], [out])
    assert stamp_path([out]).is_file()
    assert is_fresh(args, [src], [out])


def test_each_change_makes_the_stage_stale(tmp_path):
    src, out = _stage(tmp_path)
    args = ["sync", "x"]
    write_stamp(args, [src], [out])
    assert not is_fresh([*args, "--seed", "1"], [src], [out])       # another option
    (src / "b.txt").write_text("new input")                            # a new file in a folder
    assert not is_fresh(args, [src], [out])
    (src / "b.txt").unlink()
    assert is_fresh(args, [src], [out])
    (src / "a.txt").write_text("edited")                               # an edited input
    assert not is_fresh(args, [src], [out])
    (src / "a.txt").write_text("a")
    out.write_text("tampered")                                         # a modified output
    assert not is_fresh(args, [src], [out])
    out.unlink()                                                       # a deleted output
    assert not is_fresh(args, [src], [out])

"""The interior as data: a NIfTI label volume in the phantom frame and each label's ratio.

Known truth: volumes built here voxel by voxel (a ball of label 1 at a known place), read back
through nibabel; and every refusal the issue names, one line naming the file.
"""

from __future__ import annotations

import gzip
from pathlib import Path

import nibabel as nib
import numpy as np
import pytest

from core.errors import BadInput
from data_schema.interior import (
    Interior,
    check_covers,
    label_ratios,
    read_interior,
    session_interior,
    write_interior,
)

FOOTPRINT, TOP, THICKNESS = (0.1, 0.1), -0.0015, 0.032


def _ball(shape: tuple[int, int, int] = (100, 100, 36)) -> tuple[np.ndarray, np.ndarray]:
    """1 mm voxels over [0, 100]^2 x [-35.5, 0.5] mm, label 1 in a 12 mm ball at (50, 50,
    -11.5) mm."""
    affine = np.diag([1.0, 1.0, 1.0, 1.0])
    affine[:3, 3] = [0.5, 0.5, -35.0]
    idx = np.stack(np.meshgrid(*[np.arange(n) for n in shape], indexing="ij"), -1)
    mm = idx + affine[:3, 3]
    labels = (np.linalg.norm(mm - [50.0, 50.0, -11.5], axis=-1) <= 12.0).astype(np.uint8)
    return labels, affine


def _session(folder: Path, phantom: str) -> Path:
    folder.mkdir(parents=True, exist_ok=True)
    (folder / "session.toml").write_text(f"[phantom]\n{phantom}\n")
    return folder


def test_written_volume_reads_back_with_its_labels_where_they_were(tmp_path: Path) -> None:
    labels, affine = _ball()
    write_interior(tmp_path / "i.nii.gz", labels, affine)
    back = read_interior(tmp_path / "i.nii.gz")
    assert back.present() == [0, 1]
    at = np.array([[0.050, 0.050, -0.0115], [0.050, 0.050, -0.0245], [0.010, 0.010, -0.010],
                   [0.2, 0.05, -0.01]])
    assert back.label_at(at).tolist() == [1, 0, 0, -1]


def test_an_uncompressed_nii_from_nibabel_reads_as_well(tmp_path: Path) -> None:
    labels, affine = _ball()
    nib.save(nib.Nifti1Image(labels, affine), str(tmp_path / "i.nii"))
    assert read_interior(tmp_path / "i.nii").label_at(np.array([[0.05, 0.05, -0.0115]])) == 1


def _box(thickness: float) -> tuple[np.ndarray, np.ndarray]:
    """The block's lowest and highest corners: the footprint, ``thickness`` below TOP."""
    return np.array([0.0, 0.0, TOP - thickness]), np.array([*FOOTPRINT, TOP])


def test_volume_covering_the_block_passes_and_a_short_one_is_refused(tmp_path: Path) -> None:
    labels, affine = _ball()
    check_covers(Interior(labels, affine), "i.nii.gz", *_box(THICKNESS))
    with pytest.raises(BadInput, match="does not cover the block.*along z"):
        check_covers(Interior(labels[:, :, 10:], affine), "i.nii.gz", *_box(0.032))


def test_affine_in_metres_disagrees_with_the_footprint(tmp_path: Path) -> None:
    labels, affine = _ball()
    metres = affine.copy()
    metres[:3, :3] *= 1000.0                    # voxels of 1 m: a volume a thousand times off
    with pytest.raises(BadInput, match="disagrees with the footprint"):
        check_covers(Interior(labels, metres), "i.nii.gz", *_box(THICKNESS))


@pytest.mark.parametrize(("data", "match"), [
    (np.full((4, 4, 4), np.nan, dtype=np.float32), "NaN"),
    (np.full((4, 4, 4), 1.5, dtype=np.float32), "whole numbers"),
    (np.zeros((4, 4, 4, 2), dtype=np.uint8), "3-D"),
])
def test_bad_volumes_are_refused_in_one_line(tmp_path: Path, data: np.ndarray, match: str
                                              ) -> None:
    path = tmp_path / "bad.nii.gz"
    path.write_bytes(gzip.compress(nib.Nifti1Image(data, np.eye(4)).to_bytes()))
    with pytest.raises(BadInput, match=match) as e:
        read_interior(path)
    assert str(path) in e.value.line() and "\n" not in e.value.line()


def test_a_file_that_is_not_nifti_is_refused(tmp_path: Path) -> None:
    path = tmp_path / "i.nii.gz"
    path.write_bytes(b"\x1f\x8b" + b"not a volume" * 10)
    with pytest.raises(BadInput, match="not a NIfTI volume"):
        read_interior(path)


def test_labels_need_a_ratio_each_within_range_or_fit() -> None:
    assert label_ratios({"1": 3.0, "2": "fit"}, [0, 1, 2], "s.toml") == {0: 1.0, 1: 3.0, 2: None}
    with pytest.raises(BadInput, match="label 2 of the interior has no ratio"):
        label_ratios({"1": 3.0}, [0, 1, 2], "s.toml")
    with pytest.raises(BadInput, match="must be in \\[0.1, 20\\]"):
        label_ratios({"1": 25.0}, [0, 1], "s.toml")
    with pytest.raises(BadInput, match="must be in"):
        label_ratios({"1": float("nan")}, [0, 1], "s.toml")
    with pytest.raises(BadInput, match="has only labels"):
        label_ratios({"3": 2.0}, [0, 1], "s.toml")


def test_session_toml_names_the_volume_and_its_labels(tmp_path: Path) -> None:
    labels, affine = _ball()
    folder = _session(tmp_path / "s", 'interior = "i.nii.gz"\n[phantom.labels]\n1 = "fit"')
    write_interior(folder / "i.nii.gz", labels, affine)
    spec = session_interior(folder)
    assert spec is not None and spec.ratios == {0: 1.0, 1: None}
    assert session_interior(_session(tmp_path / "plain", 'size_mm = [100.0, 100.0]')) is None
    missing = _session(tmp_path / "m", 'interior = "absent.nii.gz"')
    with pytest.raises(BadInput, match="does not exist"):
        session_interior(missing)


def _ct(labels: np.ndarray, seed: int = 0) -> np.ndarray:
    """A CT-like volume of ``labels``: silicone about 60, the inclusion about 300 (HU-like),
    each voxel with noise."""
    noise = np.random.default_rng(seed).normal(0.0, 15.0, labels.shape)
    return np.where(labels == 1, 300.0, 60.0) + noise


def test_a_ct_with_an_intensity_table_gives_the_labels_it_was_made_from(tmp_path: Path
                                                                        ) -> None:
    labels, affine = _ball()
    folder = _session(tmp_path / "s", 'interior = "ct.nii.gz"\n[phantom.labels]\n1 = 3.0\n'
                                      '[phantom.intensities]\n0 = [-1000, 180]\n1 = [180, 3000]')
    nib.save(nib.Nifti1Image(_ct(labels).astype(np.float32), affine), str(folder / "ct.nii.gz"))
    spec = session_interior(folder)
    assert spec is not None and spec.ratios == {0: 1.0, 1: 3.0}
    assert np.array_equal(spec.interior.labels, labels)


@pytest.mark.parametrize(("table", "match"), [
    ('0 = [-1000, 100]\n1 = [180, 3000]', r"voxel\(s\) fall in no .* range"),
    ('0 = [-1000, 200]\n1 = [180, 3000]', "ranges of labels 0 and 1 overlap"),
    ('0 = [180, -1000]\n1 = [180, 3000]', "low < high"),
    ('x = [0, 1]', "not a label number"),
])
def test_an_intensity_table_that_does_not_sort_every_voxel_is_refused(
        tmp_path: Path, table: str, match: str) -> None:
    labels, affine = _ball((20, 20, 20))
    folder = _session(tmp_path / "s", f'interior = "ct.nii"\n[phantom.intensities]\n{table}')
    nib.save(nib.Nifti1Image(_ct(labels).astype(np.float32), affine), str(folder / "ct.nii"))
    with pytest.raises(BadInput, match=match) as e:
        session_interior(folder)
    assert "\n" not in e.value.line()


def test_a_ct_without_its_table_is_refused_as_no_label_map(tmp_path: Path) -> None:
    labels, affine = _ball((20, 20, 20))
    path = tmp_path / "ct.nii"
    nib.save(nib.Nifti1Image(_ct(labels).astype(np.float32), affine), str(path))
    with pytest.raises(BadInput, match="need a \\[phantom.intensities\\] table"):
        read_interior(path)

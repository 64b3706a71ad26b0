"""A QTM TSV motion export read by what its header lists (`ingest/qtm_motion.py`), and
files that are no 3D or 6D export refused."""

from __future__ import annotations

import pytest
from helpers.qtm_files import NEW_3D, OLD_6D, refused

from core.series import BodySeries, MarkerSeries
from ingest.qtm_motion import read_qtm_tsv

pytestmark = pytest.mark.usefixtures("real_samples")


def test_read_qtm_tsv_dispatches_on_header_keys():
    assert isinstance(read_qtm_tsv(NEW_3D), MarkerSeries)
    assert isinstance(read_qtm_tsv(OLD_6D), BodySeries)


@pytest.mark.parametrize("content", [
    b"hello world\nthis is not a mocap export\n",
    b"\x00\x01\x02binary" * 50,
    b"",
    b"NO_OF_FRAMES\t2\nDATA_INCLUDED\t2D\n1\t2\n3\t4\n",
])
def test_bad_unknown_or_unsupported_file(tmp_path, content):
    p = tmp_path / "x.tsv"
    p.write_bytes(content)
    refused(p)

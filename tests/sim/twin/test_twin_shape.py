"""The curved twin: a dome's analytic cap, a mould file's top, the lattice stretched to it, the
markers resting on it and the presses square to it within a hand's angles; the truth that
sync and extract are checked against (the rest surface on the mould, depth along the normal)."""

from __future__ import annotations

from dataclasses import replace
from pathlib import Path

import numpy as np
import pytest

from benchmarks.bench_curved import write_half_cylinder
from core.errors import BadInput
from sim.twin.indenter import HandStyle
from sim.twin.phantom import Phantom, PhantomSpec
from sim.twin.synth_params import SynthParams
from sim.twin.synth_stage import phantom_spec
from sim.twin.twin import simulate_twin
from sim.twin.twin_scene import TwinParams
from sim.twin.twin_shape import parse_shape

SIZE = PhantomSpec.size


def test_a_dome_is_a_spherical_cap_over_the_block() -> None:
    top = parse_shape("dome:30", SIZE)
    z = top.top(np.array([[0.0, 0.0], [0.05, 0.05], [0.05, 0.0]]))
    half = np.hypot(*SIZE[:2]) / 2
    radius = (half ** 2 + 0.03 ** 2) / 0.06
    edge = np.sqrt(radius ** 2 - 0.05 ** 2) - (radius - 0.03)      # mid-edge, analytic
    np.testing.assert_allclose(z, [SIZE[2] + 0.03, SIZE[2], SIZE[2] + edge], atol=0.02e-3)


def test_the_lattice_reaches_a_mould_files_top(tmp_path: Path) -> None:
    spec = phantom_spec(shape=str(write_half_cylinder(tmp_path / "c.obj", radius_mm=50.0)))
    assert spec.size[:2] == pytest.approx((0.1, 0.1))
    ph = Phantom(spec)
    top = ph.rest[ph.grid[:, :, -1]]
    y = top[..., 1]                              # twin frame: the axis along x at y = 0
    expect = np.sqrt(np.maximum(0.05 ** 2 - y ** 2, 0.0))
    inner = np.abs(y) < 0.045
    np.testing.assert_allclose(top[..., 2][inner], expect[inner], atol=0.2e-3)   # the facets


@pytest.fixture(scope="module")
def dome_twin():
    s = SynthParams(seed=4, locations=3, repeats=1, shape="dome:30")
    return simulate_twin(TwinParams(**s.session_fields(),
                                    phantom=phantom_spec(shape=s.shape)))


def test_rest_surface_and_markers_lie_on_the_mould(dome_twin) -> None:
    spec = dome_twin.phantom.spec
    shape_to_lab = dome_twin.to_lab @ np.linalg.inv(spec.shape.to_shape())
    back = np.linalg.inv(shape_to_lab)
    nodes = dome_twin.lab(dome_twin.phantom.rest[dome_twin.phantom.grid[:, :, -1]])
    on = spec.shape.shape.closest((nodes.reshape(-1, 3) @ back[:3, :3].T) + back[:3, 3])[2]
    assert np.abs(on).max() < 0.02e-3           # the lattice's top on the mould's facets
    markers = dome_twin.mocap.points[0, :-1] @ back[:3, :3].T + back[:3, 3]
    off = spec.shape.shape.closest(markers)[2]
    np.testing.assert_allclose(off, spec.marker_radius, atol=0.05e-3)


def test_presses_are_square_to_the_surface_within_a_hands_angles(dome_twin) -> None:
    ph, nodes = dome_twin.phantom, dome_twin.nodes
    """Against the dome's sphere: its normal at each contact, in the lab."""
    half = np.hypot(*SIZE[:2]) / 2
    radius = (half ** 2 + 0.03 ** 2) / 0.06
    centre = np.array([0.0, 0.0, SIZE[2] + 0.03 - radius])           # twin frame
    tilts, slopes = [], []
    for press in dome_twin.hand.presses:
        at = ph.contact_point(tuple(nodes[press.location]))
        normal = dome_twin.to_lab[:3, :3] @ ((at - centre) / np.linalg.norm(at - centre))
        tilts.append(np.degrees(np.arccos(-press.direction @ normal)))
        slopes.append(np.degrees(np.arccos(normal[2])))
    assert max(tilts) <= HandStyle.max_tilt_deg + 1.0      # the lattice's normal, to 1 degree
    assert max(slopes) > 10.0                    # the places are on the dome's flanks too


def test_a_shape_with_inclusions_or_a_bad_dome_is_refused() -> None:
    with pytest.raises(BadInput, match="one silicone"):
        replace(phantom_spec(shape="dome:30"), layer=SynthParams(layer="3,2").regions()[1])
    for bad in ("dome:0.2", "dome:high"):
        with pytest.raises(BadInput, match="dome"):
            parse_shape(bad, SIZE)


@pytest.mark.parametrize("args, what", [(["--shape", "dome:100"], "dome's height"),
                                        (["--shape", "dome:30", "--layer", "3,2"],
                                         "one silicone"),
                                        (["--shape", "absent.stl"], "does not exist")])
def test_synth_refuses_a_bad_shape_in_one_line(tmp_path: Path, args, what) -> None:
    from click.testing import CliRunner

    from pipeline.cli import cli

    res = CliRunner().invoke(cli, ["-q", "synth", str(tmp_path / "s"), *args])
    assert res.exit_code == 2
    line = res.stderr.strip()
    assert "\n" not in line and what in line
    assert not (tmp_path / "s").exists()

"""The synth stage runner: the phantom twin's session folder, what the lab would hand over,
plus the truth.

``run_synth`` plays a session (:func:`sim.twin.twin.simulate_twin`) and writes it in the
lab's formats (:mod:`sim.twin.lab_writers`, :mod:`ingest.ati_cal`) with ``truth.h5``
(:mod:`sim.twin.twin_truth`, its provenance recorded here) and, when asked, a rerun recording
(:mod:`sim.twin.synth_view`). The same seed gives the same bytes of every data file. Its
settings: :mod:`sim.twin.synth_params`.

Writing over an earlier session removes its files that the new one does not write (another
sensor's ``FT<serial>.cal``, a recording) and leaves every other file alone.
"""

from __future__ import annotations

import re
from dataclasses import asdict, replace
from pathlib import Path

import numpy as np

from core.atomic import atomic_outputs
from core.errors import BadInput
from core.provenance import make_provenance
from data_schema.truth import TRUTH
from sim.twin.marker_layout import parse_layout, parse_size
from sim.twin.phantom import PhantomSpec
from sim.twin.synth_params import SynthParams
from sim.twin.synth_view import write_twin_recording
from sim.twin.twin import Twin, simulate_twin
from sim.twin.twin_files import FILES, RECORDING, calibration_name, file_keys, write_lab_files
from sim.twin.twin_scene import TwinParams
from sim.twin.twin_shape import DOME, parse_shape
from sim.twin.twin_truth import write_truth


def run_synth(inputs: None, out: str | Path, params: SynthParams | None = None,
              rrd: str | Path | None = None) -> Path:
    """Simulate a session and write its folder ``out`` (see the module docstring); returns
    the folder. Reads nothing (``inputs`` is None).

    ``params.markers`` (``RxC`` or ``scattered:N``), ``marker_pitch_mm`` and ``size``
    (``LxW`` mm) lay out the phantom (:mod:`sim.twin.marker_layout`), ``inclusions`` and
    ``layer`` its other silicones (:mod:`sim.twin.material_regions`); ``rrd`` also writes a
    rerun recording of press ``params.view_press``.
    """
    s = params or SynthParams()
    inclusions, layer = s.regions()
    spec = replace(phantom_spec(s.markers, s.marker_pitch_mm, s.size, s.seed, s.shape),
                   inclusions=inclusions, layer=layer)
    p = TwinParams(**s.session_fields(), phantom=spec)
    folder = _output_folder(out)
    if rrd is not None and not 0 <= s.view_press < s.places * s.repeats:
        raise BadInput("--view-press",
                       f"press {s.view_press} does not exist (0..{s.places * s.repeats - 1})")
    twin = simulate_twin(p)
    write_twin(twin, folder, s, rrd)
    return folder


def phantom_spec(markers: str = SynthParams.markers,
                 marker_pitch_mm: float = SynthParams.marker_pitch_mm,
                 size: str = SynthParams.size, seed: int = SynthParams.seed,
                 shape: str | None = SynthParams.shape) -> PhantomSpec:
    """The block of ``--markers``, ``--marker-pitch``, ``--size`` (thickness as default) and
    ``--shape`` (a file's footprint is its own: ``--size`` gives way to it)."""
    base = PhantomSpec()
    size_m = (*parse_size(size), base.size[2])
    top = None if shape is None else parse_shape(shape, size_m)
    if top is not None and shape is not None and not shape.startswith(DOME):
        height = float(np.ptp(top.shape.vertices[:, 2]))
        size_m = (*top.footprint, height)
    return replace(base, size=size_m, shape=top,
                   markers=parse_layout(markers, marker_pitch_mm, seed))


def _output_folder(out_dir: str | Path) -> Path:
    """The session folder: new, empty, or an earlier twin session (then overwritten)."""
    folder = Path(out_dir)
    if folder.exists() and not folder.is_dir():
        raise BadInput(folder, "exists and is not a folder")
    if folder.is_dir() and any(folder.iterdir()) and not (folder / FILES["truth"]).is_file():
        raise BadInput(folder, "folder is not empty and holds no earlier synthetic session; "
                               "choose a new or empty folder")
    return folder


def write_twin(twin: Twin, folder: str | Path, params: SynthParams,
               rrd: str | Path | None = None) -> None:
    """Write every file of the session folder (atomically: all or nothing): ``twin``, the
    session ``params`` asked for (truth.h5's provenance records them), and the recording of
    press ``params.view_press`` where ``rrd`` is given.

    Over an earlier session (the folder holds a ``truth.h5``), the files that session wrote
    and this one does not (another sensor's ``FT<serial>.cal``, a ``recording.rrd`` this run
    skips, the other force route's files) are removed once the new files are in place; no
    other file is touched.
    """
    folder = Path(folder)
    earlier = (folder / FILES["truth"]).is_file()
    keys = file_keys(twin)
    finals = [folder / FILES[k] for k in keys]
    cal_name = calibration_name(twin)
    cal = None if cal_name is None else folder / cal_name
    if rrd is not None and Path(rrd).resolve() in {f.resolve() for f in finals}:
        raise BadInput(rrd, "--rrd names one of the session files synth writes")
    provenance = make_provenance("synth", asdict(params), [], TRUTH.name, TRUTH.version)
    with atomic_outputs(*finals, cal, rrd) as tmps:
        out = {k: t for k, t in zip([*keys, "cal", "rrd"], tmps, strict=True) if t is not None}
        write_lab_files(twin, out)
        write_truth(out["truth"], twin, provenance)
        if "rrd" in out:
            write_twin_recording(twin, out["rrd"], params.view_press)
    if earlier:
        _remove_stale(folder, [*finals, cal, rrd])


def _remove_stale(folder: Path, written: list[Path | str | None]) -> None:
    """Remove the files of an earlier session in ``folder`` that this one did not write."""
    keep = {Path(f).resolve() for f in written if f is not None}
    for f in folder.iterdir():
        if f.is_file() and _twin_file(f.name) and f.resolve() not in keep:
            f.unlink()


def _twin_file(name: str) -> bool:
    """Whether a session folder's file named ``name`` is one the twin writes."""
    return (name in FILES.values() or name == RECORDING
            or re.fullmatch(r"FT\d{5}\.cal", name) is not None)

"""The synth stage runner: the phantom twin's session folder, what the lab would hand over,
plus the truth.

``run_synth`` plays a session (:func:`sim.twin.twin.simulate`) and writes it in the lab's
formats (:mod:`sim.twin.lab_writers`, :mod:`ingest.ati_cal`) with ``truth.h5``
(:mod:`sim.twin.twin_truth`) and, when asked, a rerun recording (:mod:`sim.twin.synth_view`).
The same seed gives the same bytes of every data file.

Writing over an earlier session removes its files that the new one does not write (another
sensor's ``FT<serial>.cal``, a recording) and leaves every other file alone.
"""

from __future__ import annotations

import re
from dataclasses import replace
from pathlib import Path

from core.atomic import atomic_outputs
from core.errors import BadInput
from sim.twin.marker_layout import parse_layout, parse_size
from sim.twin.phantom import PhantomSpec
from sim.twin.synth_view import write_twin_recording
from sim.twin.twin import Twin, simulate
from sim.twin.twin_files import FILES, RECORDING, calibration_name, file_keys, write_lab_files
from sim.twin.twin_scene import TwinParams
from sim.twin.twin_truth import write_truth


def run_synth(out_dir: str | Path, seed: int = 0, locations: int = 5, repeats: int = 4,
              rrd: str | Path | None = None, view_press: int = 0, markers: str = "5x5",
              marker_pitch_mm: float = 20.0, size: str = "100x100",
              **params: object) -> Path:
    """Simulate a session and write its folder (see the module docstring); returns the folder.

    ``markers`` (``RxC`` or ``scattered:N``), ``marker_pitch_mm`` and ``size`` (``LxW`` mm)
    lay out the phantom (:mod:`sim.twin.marker_layout`); ``params`` are further
    :class:`TwinParams` fields (``rate_hz``: the mocap's frame rate); ``rrd`` also writes a
    rerun recording of press ``view_press``.
    """
    spec = phantom_spec(markers, marker_pitch_mm, size, seed)
    p = TwinParams(seed=seed, locations=locations, repeats=repeats, phantom=spec, **params)
    folder = _output_folder(out_dir)
    if rrd is not None and not 0 <= view_press < locations * repeats:
        raise BadInput("--view-press",
                       f"press {view_press} does not exist (0..{locations * repeats - 1})")
    twin = simulate(p)
    write_twin(twin, folder, rrd, view_press)
    return folder


def phantom_spec(markers: str = "5x5", marker_pitch_mm: float = 20.0, size: str = "100x100",
                 seed: int = 0) -> PhantomSpec:
    """The block of ``--markers``, ``--marker-pitch`` and ``--size`` (thickness as default)."""
    base = PhantomSpec()
    footprint = parse_size(size)
    return replace(base, size=(*footprint, base.size[2]),
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


def write_twin(twin: Twin, folder: str | Path, rrd: str | Path | None = None,
               view_press: int = 0) -> None:
    """Write every file of the session folder (atomically: all or nothing).

    Over an earlier session (the folder holds a ``truth.h5``), the files that session wrote
    and this one does not (another sensor's ``FT<serial>.cal``, a ``recording.rrd`` this run
    skips, the other force route's files) are removed once the new files are in place; no
    other file is touched.
    """
    folder = Path(folder)
    earlier = (folder / FILES["truth"]).is_file()
    keys = file_keys(twin)
    finals = [folder / FILES[k] for k in keys] + [folder / calibration_name(twin)]
    if rrd is not None and Path(rrd).resolve() in {f.resolve() for f in finals}:
        raise BadInput(rrd, "--rrd names one of the session files synth writes")
    with atomic_outputs(*finals, rrd) as tmps:
        out = dict(zip([*keys, "cal", "rrd"], tmps, strict=True))
        write_lab_files(twin, out)
        write_truth(out["truth"], twin)
        if out["rrd"] is not None:
            write_twin_recording(twin, out["rrd"], view_press)
    if earlier:
        _remove_stale(folder, [*finals, rrd])


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

"""QTM analog TSV exports (``<trial>_a.tsv``): one analog board's channels, in volts as QTM wrote
them (gain 1), with no value missing. Where the export has its SAMPLE column, the samples keep
their numbers: a capture with lost samples (a hole) stays a jump in time.
"""

from __future__ import annotations

from pathlib import Path

import numpy as np

from core.errors import BadInput
from core.holes import counted_numbers
from ingest.analog import AnalogExport, check_scales
from ingest.qtm_block import parse_block, require_data
from ingest.qtm_header import count, finite, rate_problem
from ingest.qtm_scan import QtmHead, export_meta, key_line, scan_export

_ANALOG_LEAD = ("SAMPLE", "TIME")        # the analog export's leading columns


def read_qtm_analog(path: str | Path) -> AnalogExport:
    """Read a QTM analog TSV export (``<trial>_a.tsv``): one analog board's channels.

    Header keys (QTM's manual): ``TOT_NO_OF_CHAN``, ``NO_OF_SAMPLES`` (older exports),
    ``FREQUENCY`` or per-channel ``CHANNEL_FREQUENCIES`` and ``CHANNEL_SAMPLE_COUNTS``,
    ``CHANNEL_NAMES``, ``CHANNEL_GAIN`` (QTM writes 1), optionally ``CHANNEL_UNITS`` (else volts);
    then an optional ``SAMPLE TIME <names>`` column line and the samples. The first sample is at
    the first 3D frame of the same capture.
    """
    head = scan_export(path, "CHANNEL_NAMES", "analog")
    names = [n.strip() for n in head.keys["CHANNEL_NAMES"]]
    n = len(names)
    problem = _analog_header_problem(head, names)
    if problem is not None:
        key, what = problem
        raise head.bad(what, key_line(head, key))
    rate = _analog_rate(head, n)
    gains = _analog_list(head, "CHANNEL_GAIN", n, 1.0)
    try:
        check_scales(path, "CHANNEL_GAIN", gains, n)
    except BadInput as e:
        raise head.bad(e.what, key_line(head, "CHANNEL_GAIN")) from None
    if np.any(gains != 1.0):
        raise head.bad("CHANNEL_GAIN other than 1: QTM writes its analog values with gain 1, "
                       "a file with other gains is not understood", key_line(head, "CHANNEL_GAIN"))
    units = [u.strip() for u in head.keys.get("CHANNEL_UNITS", ["V"] * n)]
    if len(units) != n:
        raise head.bad(f"CHANNEL_UNITS has {len(units)} entries for {n} channels",
                       key_line(head, "CHANNEL_UNITS"))
    require_data(head)
    n_fields, time_col, cols = _layout_analog(head, names)
    counted = time_col is not None                   # SAMPLE (column 0), then TIME
    t, block = parse_block(head, n_fields, time_col, [0] * counted + cols)
    values = block[:, counted:]
    numbers = counted_numbers(block[:, 0], path) if counted else None
    _check_samples(head, values, rate, t, numbers)
    return AnalogExport(source=str(path), format="qtm_tsv_analog", labels=names,
                        descriptions=[""] * n, units=units, scales=gains, offsets=np.zeros(n),
                        gen_scale=1.0, rate_hz=rate, values=values,
                        meta={**export_meta(head, "qtm_tsv_analog", units[0] if units else "V"),
                              "units_stated": "CHANNEL_UNITS" in head.keys},
                        numbers=numbers)


def _analog_header_problem(head: QtmHead, names: list[str]) -> tuple[str, str] | None:
    """CHANNEL_NAMES: none empty, none twice, as many as TOT_NO_OF_CHAN says."""
    if not names or not all(names):
        return "CHANNEL_NAMES", "CHANNEL_NAMES has an empty name" if names else \
            "CHANNEL_NAMES lists no channels"
    dups = sorted({x for x in names if names.count(x) > 1})
    if dups:
        return "CHANNEL_NAMES", f"duplicate name(s) in CHANNEL_NAMES: {', '.join(dups)}"
    said = head.scalar("TOT_NO_OF_CHAN")
    if said is not None and count(said) != len(names):
        return "TOT_NO_OF_CHAN", (f"TOT_NO_OF_CHAN is {said} but CHANNEL_NAMES lists "
                                  f"{len(names)} names")
    return None


def _analog_list(head: QtmHead, key: str, n: int, default: float) -> np.ndarray:
    """A per-channel numeric header list (CHANNEL_GAIN, CHANNEL_FREQUENCIES, ...)."""
    values = head.keys.get(key)
    if values is None:
        return np.full(n, default)
    numbers = [finite(v) for v in values]
    if len(numbers) != n or any(v is None for v in numbers):
        raise head.bad(f"{key} must hold {n} numbers, one per channel", key_line(head, key))
    return np.array(numbers, dtype=np.float64)


def _analog_rate(head: QtmHead, n: int) -> float:
    """The sample rate: CHANNEL_FREQUENCIES (all alike) or FREQUENCY."""
    if "CHANNEL_FREQUENCIES" in head.keys:
        rates = _analog_list(head, "CHANNEL_FREQUENCIES", n, 0.0)
        if np.any(rates != rates[0]):
            raise head.bad("CHANNEL_FREQUENCIES differ between channels; the force channels "
                           "must share one rate", key_line(head, "CHANNEL_FREQUENCIES"))
        rate: float | None = float(rates[0])
    else:
        rate = head.number("FREQUENCY")
    if rate is None or not (np.isfinite(rate) and rate > 0):
        raise head.bad("no analog rate: FREQUENCY or CHANNEL_FREQUENCIES must be a number > 0")
    return float(rate)


def _layout_analog(head: QtmHead, names: list[str]) -> tuple[int, int | None, list[int]]:
    """Fields per row, the TIME column (or None) and each channel's column."""
    assert head.first is not None
    n_fields = len(head.first)
    if head.labels is not None:
        labels = [x.strip() for x in head.labels]
        lead = [x.upper() for x in labels[:2]]
        k = next((i for i in (2, 1, 0) if lead[:i] == list(_ANALOG_LEAD[:i])), 0)
        if labels[k:] != names:
            raise head.bad("column line does not name the channels of CHANNEL_NAMES in their "
                           "order", head.labels_line)
        time_col = 1 if k == 2 else None
    else:
        core = n_fields - (1 if not head.first[-1].strip() else 0)      # a trailing tab
        k = core - len(names)
        if k not in (0, 2):
            raise head.bad(f"row has {n_fields} fields; {len(names)} channels need "
                           f"{len(names)} (or {len(names) + 2} with SAMPLE and TIME)",
                           head.first_line)
        time_col = 1 if k == 2 else None
    return n_fields, time_col, list(range(k, k + len(names)))


def _check_samples(head: QtmHead, values: np.ndarray, rate: float, t: np.ndarray | None,
                   numbers: np.ndarray | None) -> None:
    """NO_OF_SAMPLES / CHANNEL_SAMPLE_COUNTS against the rows; the TIME column against the
    rate over the samples' numbers; no channel may miss a value in a row."""
    n = len(values)
    counts = [count(v) for v in head.keys.get("CHANNEL_SAMPLE_COUNTS", [])]
    said = head.scalar("NO_OF_SAMPLES")
    for key, value in [("NO_OF_SAMPLES", None if said is None else count(said))] + \
            [("CHANNEL_SAMPLE_COUNTS", c) for c in counts]:
        if (key == "CHANNEL_SAMPLE_COUNTS" or said is not None) and value != n:
            raise head.bad(f"{key} says {head.keys[key][0].strip() if value is None else value}"
                           f" samples but the file has {n} rows", key_line(head, key))
    bad = np.argwhere(np.isnan(values))
    if bad.size:
        row, col = bad[0]
        raise head.bad(f"analog channel {col + 1} has no value", head.first_line + int(row))
    if t is not None:
        counted = n if numbers is None else int(numbers[-1]) + 1
        off = rate_problem(rate, counted, float(t[-1] - t[0]))
        if off is not None:
            raise head.bad(off.replace("FREQUENCY", "the analog rate").replace(
                "Time column", "TIME column").replace("frames", "samples"), head.first_line)

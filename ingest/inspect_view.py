"""The inspect view: a summary (:func:`ingest.inspect_stage.run_inspect`) as the text a person
reads, one line per fact: the format, frames and rate, names, missing samples, units, events,
analog channels (one line each), calibration, schema, streams, datasets, rerun entities, the
format's details and the provenance.
"""

from __future__ import annotations

from pathlib import Path
from typing import Any

from core.text import one_line

_SHOWN = ("format", "units_in_file")      # details already shown by the lines above them


def format_summary(s: dict[str, Any]) -> str:
    """A readable multi-line text of a summary."""
    lines = [f"{s['path']}", f"  format:      {s['format']}"]
    if s["frames"] is not None:
        rate = f" at {s['rate_hz']:g} Hz" if s["rate_hz"] else ""
        dur = f" ({s['duration_s']:.3f} s)" if s["duration_s"] is not None else ""
        lines.append(f"  frames:      {s['frames']}{rate}{dur}")
    for key in ("markers", "bodies", "channels"):
        if s[key] is not None:
            lines.append(f"  {key + ':':12} {len(s[key])}: {', '.join(s[key])}")
    if s["missing_samples"] is not None:
        lines.append(f"  missing:     {s['missing_samples']} samples")
    if s["holes"]:
        lines.append(f"  holes:       {len(s['holes'])}: " + "; ".join(s["holes"]))
    if s["units"]:
        lines.append("  units:       " + ", ".join(f"{k} {v}" for k, v in s["units"].items()))
    if s["events"]:
        lines.append(f"  events:      {len(s['events'])}: " + ", ".join(
            f"{label} @ {t:.3f} s" for label, t in s["events"][:8]))
    if s["analog"]:
        lines += _analog_lines(s["analog"])
    if s["calibration"]:
        c = s["calibration"]
        lines.append(f"  calibration: {c['serial']} {c['body_style']} {c['calibration']}, "
                     f"matrix {c['matrix_shape']} (SI), max load {c['max_load']} N, N*m")
    if s["schema"]:
        lines.append(f"  schema:      {s['schema']} {s['schema_version']}")
    for topic, st in (s["streams"] or {}).items():
        lines.append(f"  stream:      {topic}: {st['frames']} frames at {st['rate_hz']:g} Hz, "
                     f"{len(st['names'])} names")
    for name, d in (s["datasets"] or {}).items():
        units = f" [{d['units']}]" if d["units"] else ""
        lines.append(f"  dataset:     {name} {tuple(d['shape'])} {d['dtype']}{units}")
    for entity, kinds in (s["entities"] or {}).items():
        lines.append(f"  entity:      {entity} ({', '.join(kinds)})")
    for key, value in s["details"].items():
        if key not in _SHOWN:
            lines.append(f"  {key + ':':12} {one_line(value)}")
    if s["provenance"]:
        lines.append("  provenance:  " + _provenance_text(s["provenance"]))
    return "\n".join(lines)


def _analog_lines(a: dict[str, Any]) -> list[str]:
    """The analog channels, one line each: number, name, units, scale, offset."""
    per = a["samples_per_frame"]
    head = (f"  analog:      {len(a['channels'])} channels at {a['rate_hz']:g} Hz"
            + (f" ({per:g} per frame)" if per else "") + f", {a['samples']} samples, "
            f"gen. scale {a['gen_scale']:g}; values {a['values']}")
    width = max(len(c["name"]) for c in a["channels"])
    return [head] + [f"    {c['number']:3d} {c['name']:{width}}  {c['units'] or '-':4} "
                     f"scale {c['scale']:g}  offset {c['offset']:g}"
                     + (f"  (label {c['label']!r})" if c["label"] != c["name"] else "")
                     for c in a["channels"]]


def _provenance_text(p: Any) -> str:
    if not isinstance(p, dict):
        return one_line(p)
    head = ", ".join(f"{k} {p[k]}" for k in ("stage", "code_version", "created") if p.get(k))
    inputs = p.get("inputs") or {}
    files = "; ".join(f"{Path(k).name} sha256 {str(v)[:12]}" for k, v in inputs.items())
    return head + (f"; inputs: {files}" if files else "")

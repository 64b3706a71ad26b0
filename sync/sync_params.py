"""Every setting of the sync stage, and the check that each one has a meaning.

The fields' defaults are the command line's: ``pipeline/sync_cmd.py`` reads them here.
"""

from __future__ import annotations

from dataclasses import dataclass

from core.errors import BadInput


@dataclass(frozen=True)
class SyncParams:
    """Every setting of the sync stage (stored in the output's provenance)."""

    clock: str = "auto"              # auto (trigger when recorded, else data) | trigger | data
    max_gap_s: float = 0.020         # longest marker gap filled
    margin_s: float = 0.5            # unloaded frames kept before onset and after release
    detect_n: float = 0.5            # a press must rise above this force
    contact_n: float = 0.05          # contact level (raised to 5 noise widths if need be)
    location_radius_m: float = 0.010  # presses closer than this share a location
    max_offset_s: float | None = None  # data clock: largest offset searched (None: every
    #                                    lag at which the recordings overlap, any stamps)
    passband: float = 0.8            # resampler flat to this fraction of the mocap Nyquist
    max_fit_rms_m: float = 1.0e-3    # rigid fits with a larger residual are poor
    robust_scale_m: float = 0.3e-3   # Cauchy reweighting of the cluster fit (0: plain LS)
    tip_cutoff_hz: float = 15.0      # zero-phase low-pass of the tip track (0: off)
    min_pivot_rotation_deg: float = 5.0
    min_correlation: float = 0.5     # data-driven clock: force must follow the depth this well
    retare: bool = True              # re-tare from the rest next to every press (False: start)


def check_params(p: SyncParams) -> None:
    """Refuse settings outside their meaning (the CLI checks its options the same way)."""
    if p.clock not in ("auto", "trigger", "data"):
        raise BadInput(None, f"--clock must be auto, trigger or data, got {p.clock!r}")
    for name, value, strict in (("max_gap_s", p.max_gap_s, False),
                                ("margin_s", p.margin_s, False),
                                ("location_radius_m", p.location_radius_m, True),
                                ("detect_n", p.detect_n, True), ("contact_n", p.contact_n, True),
                                ("max_fit_rms_m", p.max_fit_rms_m, True),
                                ("robust_scale_m", p.robust_scale_m, False),
                                ("tip_cutoff_hz", p.tip_cutoff_hz, False)):
        if not (value > 0 if strict else value >= 0):
            raise BadInput(None, f"sync parameter {name} must be "
                                 f"{'positive' if strict else 'zero or more'}, got {value:g}")
    if p.max_offset_s is not None and not p.max_offset_s > 0:
        raise BadInput(None, f"sync parameter max_offset_s must be positive or None, got "
                             f"{p.max_offset_s:g}")
    if not 0 < p.passband < 1:
        raise BadInput(None, f"sync parameter passband must be in (0, 1), got {p.passband:g}")

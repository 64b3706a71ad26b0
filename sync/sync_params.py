"""Every setting of the sync stage, and the check that each one has a meaning.

The fields' defaults are the command line's: ``pipeline/sync_cmd.py`` reads them here.
"""

from __future__ import annotations

from dataclasses import dataclass

from core.errors import BadInput

CLOCKS = ("auto", "trigger", "data")   # the clock alignments --clock names


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


# The numbers that must be > 0, and those that must be >= 0 (0: off, or none): check_params
# refuses the rest, and the command line's options take their bounds from here.
POSITIVE = ("location_radius_m", "detect_n", "contact_n", "max_fit_rms_m")
AT_LEAST_ZERO = ("max_gap_s", "margin_s", "robust_scale_m", "tip_cutoff_hz")


def check_params(p: SyncParams) -> None:
    """Refuse settings outside their meaning (the CLI checks its options the same way)."""
    if p.clock not in CLOCKS:
        raise BadInput(None, f"--clock must be {', '.join(CLOCKS[:-1])} or {CLOCKS[-1]}, got "
                             f"{p.clock!r}")
    for name in POSITIVE + AT_LEAST_ZERO:
        value, strict = getattr(p, name), name in POSITIVE
        if not (value > 0 if strict else value >= 0):
            raise BadInput(None, f"sync parameter {name} must be "
                                 f"{'positive' if strict else 'zero or more'}, got {value:g}")
    if p.max_offset_s is not None and not p.max_offset_s > 0:
        raise BadInput(None, f"sync parameter max_offset_s must be positive or None, got "
                             f"{p.max_offset_s:g}")
    if not 0 < p.passband < 1:
        raise BadInput(None, f"sync parameter passband must be in (0, 1), got {p.passband:g}")

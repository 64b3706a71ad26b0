"""The twin's indenter and the hand that holds it: cluster geometry, presses, tremor, pivoting.

The indenter is a rigid body: four non-coplanar markers on its handle, the Nano17 between the
handle and the tip, and the tip a fixed offset (about 11 cm) below the markers. Its body frame
has the markers' centroid as origin and z along the shaft from the tip towards the handle; the
sensor frame has the same axes (origin at the sensor), so a press along ``d`` (into the phantom)
puts a positive ``Fz`` on the sensor.

The hand plays a press as: move to a hover point above the location (lifting between
locations), pause (unloaded: the force can be tared), approach along the press direction to the
surface, load to ``fmax`` with a minimum-jerk profile on an irregular time warp, hold, release,
retract to the hover point. A little tremor rides on all of it: sub-millimetre position tremor
in the air, a fraction of a degree of rotation tremor, a few hundredths of a newton of force
tremor in contact. Everything is an explicit function of time, so any clock can sample it.
"""

from __future__ import annotations

from dataclasses import dataclass, field

import numpy as np
from scipy.spatial.transform import Rotation

from sim.cone import cone_directions

# marker positions on the handle (mm, before centring), deliberately irregular so that every
# inter-marker distance differs (QTM identifies the body by them)
_HANDLE_MM = np.array([[32.0, 4.0, 0.0], [-14.0, 28.0, 10.0], [-18.0, -26.0, -6.0],
                       [6.0, -8.0, 38.0]])
_TIP_MM = np.array([1.2, -0.7, -118.0])       # below the handle, same frame
_SENSOR_ABOVE_TIP_MM = 22.0                   # the Nano17's origin, up the shaft from the tip
MARKER_NAMES = ("Indenter - 1", "Indenter - 2", "Indenter - 3", "Indenter - 4")
BODY_NAME = "Indenter"
GRAVITY = np.array([0.0, 0.0, -9.80665])


@dataclass(frozen=True)
class IndenterGeometry:
    """The rigid indenter in its body frame (metres)."""

    markers: np.ndarray        # (4, 3) marker centres; their centroid is the origin
    tip: np.ndarray            # (3,) tip offset
    sensor: np.ndarray         # (3,) force/torque reference point of the Nano17
    tool_mass: float = 0.003   # kg below the sensor (its weight loads the sensor)
    names: tuple[str, ...] = MARKER_NAMES

    @property
    def tool_centre(self) -> np.ndarray:
        """Centre of mass of the part below the sensor: halfway to the tip."""
        return 0.5 * (self.sensor + self.tip)


def make_indenter(rng: np.random.Generator) -> IndenterGeometry:
    """The indenter as built: the nominal design with a millimetre-scale build tolerance."""
    handle = _HANDLE_MM + rng.normal(0.0, 0.3, _HANDLE_MM.shape)
    tip = _TIP_MM + rng.normal(0.0, [0.8, 0.8, 2.0])
    centre = handle.mean(axis=0)
    tip_body = (tip - centre) * 1e-3
    return IndenterGeometry(markers=(handle - centre) * 1e-3, tip=tip_body,
                            sensor=tip_body + np.array([0.0, 0.0, _SENSOR_ABOVE_TIP_MM * 1e-3]))


def shaft_rotation(direction: np.ndarray, roll: float) -> np.ndarray:
    """Body-to-lab rotation with body z = -direction and body x at ``roll`` (rad) about it."""
    z = -np.asarray(direction, dtype=np.float64)
    z = z / np.linalg.norm(z)
    ref = np.array([np.cos(roll), np.sin(roll), 0.0])
    if abs(ref @ z) > 0.95:
        ref = np.array([0.0, 0.0, 1.0])
    x = ref - (ref @ z) * z
    x /= np.linalg.norm(x)
    return np.stack([x, np.cross(z, x), z], axis=1)


def min_jerk(s: np.ndarray) -> np.ndarray:
    """The minimum-jerk profile 0 -> 1 over s in [0, 1] (clipped outside)."""
    s = np.clip(s, 0.0, 1.0)
    return s**3 * (10.0 - 15.0 * s + 6.0 * s * s)


@dataclass
class Tremor:
    """A sum of sinusoids per axis: amplitudes (K, 3), frequencies (K,) Hz, phases (K, 3)."""

    amplitude: np.ndarray
    frequency: np.ndarray
    phase: np.ndarray

    @classmethod
    def draw(cls, rng: np.random.Generator, scale: float, band: tuple[float, float],
             axes: int = 3, parts: int = 3) -> Tremor:
        amp = scale * rng.uniform(0.5, 1.0, (parts, axes)) / np.sqrt(parts)
        return cls(amp, rng.uniform(*band, parts), rng.uniform(0, 2 * np.pi, (parts, axes)))

    def __call__(self, t: np.ndarray) -> np.ndarray:
        arg = 2 * np.pi * self.frequency[None, :, None] * t[:, None, None] + self.phase[None]
        return (self.amplitude[None] * np.sin(arg)).sum(axis=1)


@dataclass
class HandPress:
    """One press of the hand: where, along which direction, how hard, and when (mocap s)."""

    location: int              # index into the session's locations
    repeat: int
    contact: np.ndarray        # (3,) lab: the untouched surface point under the tip
    direction: np.ndarray      # (3,) lab unit vector, into the phantom
    fmax: float                # N
    roll: float                # rad: the hand's grip about the shaft
    hover_height: float        # m: the hover point is contact - hover_height * direction
    warp: float                # loading-rate irregularity, |warp| < 0.5
    times: np.ndarray = field(default_factory=lambda: np.zeros(8))
    # times: move start, at hover, approach start, contact, peak, hold end, released, retracted

    @property
    def hover(self) -> np.ndarray:
        return self.contact - self.hover_height * self.direction

    @property
    def rotation(self) -> np.ndarray:
        return shaft_rotation(self.direction, self.roll)

    def force(self, t: np.ndarray) -> np.ndarray:
        """Force magnitude profile (N) without tremor; 0 outside contact."""
        _, _, _, t3, t4, t5, t6, _ = self.times
        f = np.zeros_like(t)
        load = (t >= t3) & (t < t4)
        s = (t[load] - t3) / (t4 - t3)
        s = s + self.warp * np.sin(2 * np.pi * s) / (2 * np.pi)      # monotone time warp
        f[load] = self.fmax * min_jerk(s)
        f[(t >= t4) & (t <= t5)] = self.fmax
        rel = (t > t5) & (t <= t6)
        f[rel] = self.fmax * (1.0 - min_jerk((t[rel] - t5) / (t6 - t5)))
        return f


@dataclass
class HandState:
    """The hand at a set of times (mocap clock)."""

    press: np.ndarray          # (T,) index of the press in contact, -1 in the air
    force: np.ndarray          # (T,) N, contact force magnitude (0 in the air)
    tip_air: np.ndarray        # (T, 3) lab tip position (meaningful where press == -1)
    rotation: np.ndarray       # (T, 3, 3) body -> lab


@dataclass
class Hand:
    """A whole session of presses with tremor; evaluate it at any times."""

    presses: list[HandPress]
    rest: np.ndarray                # (3,) lab: where the hand waits before and after
    start: float                    # s: first move starts
    end: float                      # s: the recording ends
    rest_rotation: np.ndarray       # (3, 3)
    position_tremor: Tremor
    rotation_tremor: Tremor
    force_tremor: Tremor
    fade: float = 0.15              # s: position tremor fades out this close to contact

    def state(self, t: np.ndarray) -> HandState:
        t = np.asarray(t, dtype=np.float64)
        press = np.full(t.shape, -1, dtype=np.int64)
        force = np.zeros(t.shape)
        for k, p in enumerate(self.presses):
            inside = (t >= p.times[3]) & (t <= p.times[6])
            press[inside] = k
            force[inside] = p.force(t[inside])
        wobble = self.force_tremor(t)[:, 0] * np.minimum(1.0, force / 0.5)
        force = np.where(press >= 0, np.maximum(force + wobble, 0.0), 0.0)
        tip, nominal = self._path(t)
        tip = tip + self.position_tremor(t) * self._air_weight(t)[:, None]
        shake = Rotation.from_rotvec(self.rotation_tremor(t))
        rotation = (shake * Rotation.from_matrix(nominal)).as_matrix()
        return HandState(press=press, force=force, tip_air=tip, rotation=rotation)

    def max_force(self, k: int) -> float:
        """An upper bound of press ``k``'s force, tremor included."""
        return self.presses[k].fmax + float(np.abs(self.force_tremor.amplitude).sum())

    def _segments(self) -> list[tuple[float, float, np.ndarray, np.ndarray, float, int, int]]:
        """(t0, t1, from, to, lift, rotation-from press, rotation-to press); -1 = rest pose."""
        segs = []
        prev_pos, prev_rot = self.rest, -1
        for k, p in enumerate(self.presses):
            t0, t1, t2, t3, _, _, t6, t7 = p.times
            segs.append((t0, t1, prev_pos, p.hover, 0.03, prev_rot, k))
            segs.append((t1, t2, p.hover, p.hover, 0.0, k, k))
            segs.append((t2, t3, p.hover, p.contact, 0.0, k, k))
            segs.append((t3, t6, p.contact, p.contact, 0.0, k, k))
            segs.append((t6, t7, p.contact, p.hover, 0.0, k, k))
            prev_pos, prev_rot = p.hover, k
        last = self.presses[-1].times[7] if self.presses else self.start
        back = min(last + 1.0, max(self.end - 0.3, last + 1e-3))
        segs.append((last, back, prev_pos, self.rest, 0.03, prev_rot, -1))
        return segs

    def _path(self, t: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        """Nominal tip position (air) and rotation, before tremor."""
        tip = np.repeat(self.rest[None], len(t), axis=0)
        rot = np.repeat(self.rest_rotation[None], len(t), axis=0)
        segs = self._segments()
        for t0, t1, a, b, lift, ra, rb in segs:
            inside = (t >= t0) & (t <= t1)
            if not inside.any():
                continue
            s = min_jerk((t[inside] - t0) / max(t1 - t0, 1e-9))
            pos = a[None] + s[:, None] * (b - a)[None]
            pos[:, 2] += lift * np.sin(np.pi * s)
            tip[inside] = pos
            rot[inside] = _slerp(self._rotation(ra), self._rotation(rb), s)
        after = t > segs[-1][1]
        tip[after] = self.rest
        rot[after] = self.rest_rotation
        return tip, rot

    def _rotation(self, k: int) -> np.ndarray:
        return self.rest_rotation if k < 0 else self.presses[k].rotation

    def _air_weight(self, t: np.ndarray) -> np.ndarray:
        """1 in the air, fading smoothly to 0 within ``fade`` seconds of any contact."""
        gap = np.full(t.shape, np.inf)
        for p in self.presses:
            t3, t6 = p.times[3], p.times[6]
            dist = np.where(t < t3, t3 - t, np.where(t > t6, t - t6, 0.0))
            gap = np.minimum(gap, dist)
        return min_jerk(gap / self.fade)


def _slerp(a: np.ndarray, b: np.ndarray, s: np.ndarray) -> np.ndarray:
    """Rotations from ``a`` to ``b`` at fractions ``s``."""
    ra = Rotation.from_matrix(a)
    step = (ra.inv() * Rotation.from_matrix(b)).as_rotvec()
    return (ra * Rotation.from_rotvec(s[:, None] * step[None])).as_matrix()


@dataclass(frozen=True)
class HandStyle:
    """How the hand presses (durations in seconds at ``scale`` 1, drawn uniformly)."""

    move: tuple[float, float] = (0.8, 1.3)
    pause: tuple[float, float] = (0.3, 0.6)
    approach: tuple[float, float] = (0.5, 0.8)
    load: tuple[float, float] = (1.3, 2.2)
    hold: tuple[float, float] = (0.3, 0.6)
    release: tuple[float, float] = (0.7, 1.2)
    retract: tuple[float, float] = (0.4, 0.6)
    max_tilt_deg: float = 20.0
    fmax_mean: float = 6.2          # N: peak force, normal 6.2 +- 1.4 N (the paper's) ...
    fmax_sd: float = 1.4
    fmax_range: tuple[float, float] = (2.5, 8.0)   # ... truncated here (mean 5.95, sd 1.2 N)
    scale: float = 1.0              # all durations are multiplied by it

    @property
    def mean_press_s(self) -> float:
        """Mean duration of one press cycle (s)."""
        parts = (self.move, self.pause, self.approach, self.load, self.hold, self.release,
                 self.retract)
        return self.scale * sum(0.5 * (a + b) for a, b in parts)


def plan_hand(
    rng: np.random.Generator,
    targets: list[tuple[int, int, np.ndarray]],
    style: HandStyle,
    lead_in: float = 1.0,
    lead_out: float = 1.0,
) -> Hand:
    """A hand pressing each ``(location, repeat, contact point)`` in order, timed from 0.

    Press directions are uniform over the cap within ``max_tilt_deg`` of the surface normal
    (lab -z); ``fmax`` is normal, truncated to ``fmax_range`` (redrawn until inside it).
    """
    presses = []
    t = lead_in

    def span(r: tuple[float, float]) -> float:
        return style.scale * float(rng.uniform(*r))

    for loc, rep, contact in targets:
        direction = cone_directions(rng, style.max_tilt_deg)
        fmax = draw_fmax(rng, style)
        p = HandPress(location=loc, repeat=rep, contact=np.asarray(contact, dtype=np.float64),
                  direction=direction, fmax=fmax, roll=float(rng.uniform(-0.4, 0.4)),
                  hover_height=float(rng.uniform(0.02, 0.035)),
                  warp=float(rng.uniform(-0.4, 0.4)))
        steps = [span(style.move), span(style.pause), span(style.approach), span(style.load),
                 span(style.hold), span(style.release), span(style.retract)]
        p.times = t + np.concatenate([[0.0], np.cumsum(steps)])
        t = float(p.times[-1])
        presses.append(p)
    first = presses[0] if presses else None
    rest = (first.contact + np.array([0.0, 0.0, 0.06])) if first else np.array([0, 0, 0.06])
    rest_rotation = shaft_rotation(np.array([0.0, 0.0, -1.0]), 0.0)
    return Hand(
        presses=presses, rest=rest, start=lead_in, end=t + 1.0 + lead_out,
        rest_rotation=rest_rotation,
        position_tremor=Tremor.draw(rng, 0.00015, (6.0, 11.0)),
        rotation_tremor=Tremor.draw(rng, np.radians(0.15), (6.0, 11.0)),
        force_tremor=Tremor.draw(rng, 0.03, (4.0, 9.0), axes=1),
    )


def tilt_to_normals(hand: Hand, normals: list[np.ndarray]) -> None:
    """On a curved phantom, turn each press's direction (drawn about the lab's -z) about the
    inward normal of its location (``normals``: outward, lab, by location): a hand presses
    square to the surface it sees, within the same angles."""
    down = np.array([0.0, 0.0, -1.0])
    for press in hand.presses:
        turn = Rotation.align_vectors(-normals[press.location][None], down[None])[0]
        press.direction = turn.apply(press.direction)


def draw_fmax(rng: np.random.Generator, style: HandStyle) -> float:
    """A peak force from the normal distribution truncated to ``style.fmax_range``."""
    lo, hi = style.fmax_range
    while True:
        fmax = float(rng.normal(style.fmax_mean, style.fmax_sd))
        if lo <= fmax <= hi:
            return fmax


def pivot_motion(
    rng: np.random.Generator, geometry: IndenterGeometry, pivot: np.ndarray,
    times: np.ndarray, swing_deg: float = 30.0,
) -> tuple[np.ndarray, np.ndarray]:
    """Rotations (T, 3, 3) and marker positions (T, 4, 3) of the indenter swung about a divot.

    The tip stays in the divot at ``pivot`` (lab); the shaft tilts up to ``swing_deg`` in two
    directions on incommensurate frequencies and turns about itself, starting from upright.
    """
    t = np.asarray(times, dtype=np.float64)
    ramp = min_jerk(t / 1.0)
    freq = rng.uniform([0.17, 0.23, 0.09], [0.22, 0.31, 0.14])
    phase = rng.uniform(0, 2 * np.pi, 3)
    tilt = np.radians(swing_deg) * ramp[:, None] * np.sin(
        2 * np.pi * freq[None, :2] * t[:, None] + phase[None, :2])
    spin = np.radians(25.0) * ramp * np.sin(2 * np.pi * freq[2] * t + phase[2])
    tremor = Tremor.draw(rng, np.radians(0.15), (6.0, 11.0))(t)
    rot = (Rotation.from_rotvec(tremor)
           * Rotation.from_rotvec(np.column_stack([tilt, np.zeros_like(t)]))
           * Rotation.from_rotvec(np.column_stack([np.zeros((len(t), 2)), spin]))).as_matrix()
    offsets = geometry.markers - geometry.tip
    markers = pivot[None, None] + np.einsum("tij,mj->tmi", rot, offsets)
    return rot, markers

"""The paper's MSM data-generation protocol, written as a states file (``phantom.states``).

Protocol (paper, "Data generation"): ``locations`` masses drawn at random without replacement;
at each, ``directions`` force directions (the normal, pointing into the surface, plus random
directions up to 45 degrees from it, uniform on that spherical cap); along each, the force on
that one mass grows to ``fmax`` in ``steps`` equal steps, ``F_t = t fmax / steps``. Every random
choice is drawn up front from ``seed``, so a shard draws the same plan as a full run.

Layout (same as extracted lab states): sequence ``s = location * directions + direction``
holds states ``s * (steps + 1) + t`` for t = 0 (rest) .. steps; ``tip`` is the loaded mass,
``force`` the force magnitude, ``force_vector`` the force; single-step examples are
(t, t + 1) for every t of every sequence, multi-step examples ``min(15, #pairs)`` random pairs
(start, end) with end - start >= 2 per sequence (drawn without replacement, sorted).

Shards (``shard=(i, count)``, i from 0) simulate a contiguous block of locations
(``np.array_split``) and are complete states files themselves; :func:`merge_shards` joins all
``count`` of them into the arrays a one-process run writes, byte for byte.
"""

from __future__ import annotations

import json
import math
import time
from collections.abc import Sequence
from dataclasses import asdict, dataclass
from pathlib import Path

import h5py
import numpy as np

from core.errors import BadInput
from core.progress import progress
from core.provenance import make_provenance
from data_schema.hdf5 import attr_text, write_h5
from data_schema.states import STATES, validate_states
from sim.cone import cone_directions
from sim.msm import MSM, MSMError, MSMParams, unit
from sim.msm_sampling import contact_masses, sample_at
from sim.msm_static import (
    DEFAULT_TOL,
    StaticSolver,
    check_tol,
    residual,
    simulate_sequence,
)
from sim.workers import worker_pool

MULTI_PER_SEQUENCE = 15


@dataclass(frozen=True)
class Protocol:
    """What to simulate: the paper's defaults."""

    locations: int = 100
    directions: int = 11
    steps: int = 15
    fmax: float = 7.5
    max_angle_deg: float = 45.0
    seed: int = 0
    contact_radius: float = 0.0     # m: the load is shared by the masses this close (n_n)

    def check(self, n_masses: int) -> None:
        """Refuse a protocol that cannot be simulated (one line naming the parameter)."""
        for name in ("locations", "directions", "steps"):
            if getattr(self, name) < 1:
                raise BadInput(None, f"--{name} must be at least 1, got {getattr(self, name)}")
        if self.locations > n_masses:
            raise BadInput(None, f"--locations {self.locations} exceeds the {n_masses} masses")
        if not (math.isfinite(self.fmax) and self.fmax > 0):
            raise BadInput(None, f"--fmax must be a finite positive force, got {self.fmax}")
        if not 0 <= self.max_angle_deg <= 90:
            raise BadInput(None, f"max angle must be within 0..90 degrees, got "
                                 f"{self.max_angle_deg}")
        if not (math.isfinite(self.contact_radius) and 0 <= self.contact_radius < 0.05):
            raise BadInput(None, f"--contact-radius must be within [0, 0.05) m, got "
                                 f"{self.contact_radius}")

    @property
    def sequences(self) -> int:
        return self.locations * self.directions

    @property
    def multi_per_sequence(self) -> int:
        pairs = (self.steps + 1) * self.steps // 2 - self.steps   # end - start >= 2
        return min(MULTI_PER_SEQUENCE, pairs)


@dataclass(frozen=True)
class Plan:
    """Every random choice of a protocol."""

    protocol: Protocol
    nodes: np.ndarray        # (L,) loaded mass of each location
    directions: np.ndarray   # (L, D, 3) unit force directions; [:, 0] is the normal (0, 0, -1)
    multi: np.ndarray        # (L * D, M, 2) multi-step (start, end) steps of each sequence


def draw_plan(protocol: Protocol, n_masses: int, candidates: np.ndarray | None = None) -> Plan:
    """Draw locations (among ``candidates``, default every mass), directions and multi-step
    pairs from ``protocol.seed``."""
    candidates = np.arange(n_masses) if candidates is None else np.asarray(candidates)
    protocol.check(len(candidates))
    p = protocol
    rng = np.random.default_rng(p.seed)
    nodes = candidates[rng.choice(len(candidates), size=p.locations, replace=False)]
    dirs = np.empty((p.locations, p.directions, 3))
    dirs[:, 0] = (0.0, 0.0, -1.0)
    dirs[:, 1:] = cone_directions(rng, p.max_angle_deg, (p.locations, p.directions - 1))
    pairs = np.array([(s, e) for s in range(p.steps + 1) for e in range(s + 2, p.steps + 1)],
                     dtype=np.int64).reshape(-1, 2)
    multi = np.empty((p.sequences, p.multi_per_sequence, 2), dtype=np.int64)
    for s in range(p.sequences):
        pick = np.sort(rng.choice(len(pairs), size=p.multi_per_sequence, replace=False))
        multi[s] = pairs[pick]
    return Plan(p, nodes.astype(np.int64), dirs, multi)


def shard_locations(locations: int, shard: tuple[int, int] | None) -> np.ndarray:
    """The contiguous block of location indices of shard (i, count), or all of them."""
    if shard is None:
        return np.arange(locations)
    i, count = shard
    if not (0 <= i < count) or count > locations:
        raise BadInput(None, f"--shard {i}/{count}: need 0 <= I < N <= locations ({locations})")
    return np.array_split(np.arange(locations), count)[i]


def parse_shard(text: str) -> tuple[int, int]:
    """``"I/N"`` -> (I, N)."""
    try:
        i, count = (int(v) for v in text.split("/"))
    except ValueError:
        raise BadInput(None, f"--shard must look like I/N (e.g. 0/4), got {text!r}") from None
    return i, count


# -- simulation ------------------------------------------------------------------------------

@dataclass
class Simulated:
    """States of a block of locations, in file order, and what they cost."""

    locations: np.ndarray    # (l,) location indices
    points: np.ndarray       # (l * D * (steps + 1), N, 3) float32
    tips: np.ndarray         # (l * D * (steps + 1), 3) float32: the contact patch's centre
    max_residual: float      # N, largest force on any mass of any state (float64 solution)
    stored_residual: float   # N, the same of the states as stored (cast to float32)
    iterations: int
    factorizations: int
    cpu_s: float             # CPU seconds of the solves, summed over worker processes


def _simulate_location(args: tuple) -> tuple[np.ndarray, np.ndarray, float, float, int, int,
                                             float]:
    """One location, all its directions: the states (D, steps + 1, N, 3) float32 (every mass,
    or the layout's points then the tip), the tip (D, steps + 1, 3), the worst residuals of
    the float64 and of the stored float32 states, and solver counts."""
    cpu = time.process_time()
    params, node, directions, steps, fmax, tol, radius, layout = args
    model = MSM(params)
    solver = StaticSolver(model, tol)
    contact = contact_masses(model, model.rest[node, :2], radius)
    sampling = sample_at(model, layout[:, :2]) if layout is not None else None
    n_out = model.N if layout is None else len(layout) + 1
    out = np.empty((len(directions), steps + 1, n_out, 3), dtype=np.float32)
    tips = np.empty((len(directions), steps + 1, 3), dtype=np.float32)
    stored = 0.0
    for d, direction in enumerate(directions):
        states = simulate_sequence(model, contact, direction, steps, fmax, tol, solver)
        if not np.isfinite(states).all():
            raise MSMError(f"non-finite state at mass {node}, direction {d}")
        tips[d] = states[:, contact].mean(axis=1)
        if sampling is None:
            out[d] = states
        else:
            out[d, :, :-1] = layout + np.stack([sampling.displace(x - model.rest)
                                                for x in states])
            out[d, :, -1] = tips[d]
        for t in range(1, steps + 1):
            load = model.load(contact, unit(direction) * fmax * t / steps)
            x = out[d, t].astype(np.float64) if sampling is None else states[t]
            stored = max(stored, residual(model, x, load))
    stats = solver.stats           # max_residual: of every solve, i.e. every float64 state
    return (out, tips, stats.max_residual, stored, stats.iterations, stats.factorizations,
            time.process_time() - cpu)


def simulate(plan: Plan, params: MSMParams, locations: Sequence[int] | None = None,
             tol: float = DEFAULT_TOL, workers: int = 1, layout: np.ndarray | None = None
             ) -> Simulated:
    """Simulate ``locations`` (default: all) of ``plan`` with the fast static path.

    With ``layout`` (P, 3) the states hold the MSM sampled at those rest positions (a lab's
    markers: :mod:`sim.msm_sampling`) and then the tip, not every mass. ``workers``
    processes share the locations; the result does not depend on how many.
    """
    p = plan.protocol
    locs = np.arange(p.locations) if locations is None else np.asarray(locations)
    jobs = [(params, plan.nodes[loc], plan.directions[loc], p.steps, p.fmax, tol,
             p.contact_radius, layout) for loc in locs]
    per_loc = p.directions * (p.steps + 1)
    n_out = params.n * params.n if layout is None else len(layout) + 1
    points = np.empty((len(locs) * per_loc, n_out, 3), dtype=np.float32)
    tips = np.empty((len(locs) * per_loc, 3), dtype=np.float32)
    worst = stored = cpu = 0.0
    its = facts = 0
    workers = max(1, min(workers, len(jobs)))
    pool = worker_pool(workers) if workers > 1 else None
    try:
        results = pool.imap(_simulate_location, jobs) if pool else map(_simulate_location, jobs)
        with progress(results, "simulating MSM locations", length=len(jobs)) as bar:
            for k, (states, tip, w, s, i, f, c) in enumerate(bar):
                points[k * per_loc:(k + 1) * per_loc] = states.reshape(per_loc, -1, 3)
                tips[k * per_loc:(k + 1) * per_loc] = tip.reshape(per_loc, 3)
                worst, stored = max(worst, w), max(stored, s)
                its, facts, cpu = its + i, facts + f, cpu + c
    finally:
        if pool:
            pool.terminate()
            pool.join()
    return Simulated(locs, points, tips, worst, stored, its, facts, cpu)


# -- arrays and file -------------------------------------------------------------------------

def states_arrays(plan: Plan, sim: Simulated) -> dict[str, np.ndarray]:
    """The states-file datasets of a simulated block of locations."""
    p = plan.protocol
    T = p.steps + 1
    seq = (sim.locations[:, None] * p.directions + np.arange(p.directions)).ravel()
    n_seq = len(seq)
    step = np.tile(np.arange(T), n_seq)
    force = (step * (p.fmax / p.steps)).astype(np.float32)
    dirs = plan.directions[sim.locations].reshape(n_seq, 3)
    force_vector = (np.repeat(dirs, T, 0) * (step * (p.fmax / p.steps))[:, None])
    nodes = np.repeat(plan.nodes[sim.locations], p.directions * T)
    base = np.arange(n_seq)[:, None] * T
    single = base + np.arange(p.steps)
    multi = base[:, :, None] + plan.multi[seq]
    return {
        "states/points": sim.points,
        "states/valid": np.ones(sim.points.shape[:2], dtype=bool),
        "states/tip": sim.tips,
        "states/force": force,
        "states/force_vector": force_vector.astype(np.float32),
        "states/step": step.astype(np.int32),
        "states/sequence": np.repeat(seq, T).astype(np.int32),
        "states/location": np.repeat(seq // p.directions, T).astype(np.int32),
        "states/session": np.zeros(len(step), dtype=np.int32),
        "states/mass": nodes.astype(np.int32),
        "single/start": single.ravel().astype(np.int32),
        "single/end": (single + 1).ravel().astype(np.int32),
        "multi/start": multi[..., 0].ravel().astype(np.int32),
        "multi/end": multi[..., 1].ravel().astype(np.int32),
    }


def write_states(path: str | Path, arrays: dict[str, np.ndarray], attrs: dict) -> None:
    """Write an MSM states file atomically, validated against ``phantom.states``."""
    for name, data in arrays.items():
        if data.dtype.kind == "f" and not np.isfinite(data).all():
            raise MSMError(f"refusing to write non-finite values in {name}")
    write_h5(path, STATES, arrays, attrs)
    validate_states(path)


def file_attrs(plan: Plan, params: MSMParams, tol: float, provenance: dict,
               shard: tuple[int, int] | None, sim: Simulated | None = None) -> dict:
    """Root attributes of an MSM states file (shards add ``shard = "I/N"``).

    With ``sim``: ``max_residual_N``, the largest force left on any mass of any state as
    solved (float64, below ``tol``), and ``stored_residual_N``, the same of the states as
    stored: float32 rounds positions by up to ~4e-9 m at 0.1 m, which leaves ~1e-6 to 1e-5 N
    of spring force whatever ``tol`` was.
    """
    attrs = {
        "provenance": json.dumps(provenance),
        "source": "msm",
        "units_length": "m",
        "units_force": "N",
        "step_n": plan.protocol.fmax / plan.protocol.steps,
        "frame": "phantom",
        "session_names": json.dumps(["msm"]),
        "msm_params": json.dumps(params.as_dict()),
        "protocol": json.dumps(asdict(plan.protocol)),
        "solver": json.dumps({"method": "static equilibrium (preconditioned L-BFGS)",
                              "tol_N": tol}),
        "k_between": params.k_between,
        "k_fixed": params.k_fixed,
    }
    if sim is not None:
        attrs[RESIDUAL_ATTRS[0]] = sim.max_residual
        attrs[RESIDUAL_ATTRS[1]] = sim.stored_residual
    if shard is not None:
        attrs["shard"] = f"{shard[0]}/{shard[1]}"
    return attrs


def generate(out: str | Path, protocol: Protocol, params: MSMParams, *,
             tol: float = DEFAULT_TOL, workers: int = 1, shard: tuple[int, int] | None = None,
             command_params: dict | None = None, layout: np.ndarray | None = None,
             inputs: Sequence[Path] = ()) -> tuple[Simulated, dict[str, np.ndarray]]:
    """Simulate ``protocol`` (or one shard of it), write the states file ``out``; returns the
    simulation and the arrays written.

    With ``layout`` (a lab's rest points, :func:`lab_layout`) the states are the MSM sampled
    at those points plus the tip, and the loads fall inside the layout's footprint (where the
    lab pressed), so the network pre-trains on the graph it is fine-tuned on.
    """
    check_tol(tol)
    model = MSM(params)
    plan = draw_plan(protocol, model.N, None if layout is None else footprint(model, layout))
    locs = shard_locations(protocol.locations, shard)
    sim = simulate(plan, params, locs, tol, workers, layout)
    prov = make_provenance("simulate", command_params or {**asdict(protocol), "tol": tol},
                           inputs=list(inputs), schema=STATES.name,
                           schema_version=STATES.version)
    arrays = states_arrays(plan, sim)
    attrs = file_attrs(plan, params, tol, prov, shard, sim)
    if layout is not None:
        attrs["layout"] = json.dumps(np.asarray(layout, dtype=float).round(9).tolist())
    write_states(out, arrays, attrs)
    return sim, arrays


def footprint(model: MSM, layout: np.ndarray) -> np.ndarray:
    """The masses inside the bounding box of a layout's points in the plane."""
    lo, hi = layout[:, :2].min(axis=0), layout[:, :2].max(axis=0)
    xy = model.rest[:, :2]
    return np.flatnonzero(((xy >= lo) & (xy <= hi)).all(axis=1))


def lab_layout(path: str | Path) -> np.ndarray:
    """The rest positions (P, 3) of a lab states file's surface points, phantom frame.

    Each point's median over the sequences' rest states (step 0), ignoring the instants it
    was missing; the tip (the last point, which sits at ``states/tip``) is left out.
    """
    path = Path(path)
    validate_states(path)
    with h5py.File(path, "r") as f:
        if attr_text(f.attrs["source"]) != "lab":
            raise BadInput(path, "--layout needs extracted lab states (source 'lab')")
        rest = f["states/step"][()] == 0
        points = f["states/points"][()][rest].astype(float)
        valid = f["states/valid"][()][rest]
        tips = f["states/tip"][()][rest].astype(float)
    if not np.allclose(points[:, -1], tips, atol=1e-6, equal_nan=True):
        raise BadInput(path, "its last point is not the tip: not a lab states layout")
    points = np.where(valid[..., None], points, np.nan)[:, :-1]
    seen = np.isfinite(points).all(axis=-1).any(axis=0)
    if not seen.all():
        raise BadInput(path, f"point {int(np.flatnonzero(~seen)[0])} is never seen at rest: "
                             "no layout for it")
    return np.nanmedian(points, axis=0)


# -- merge -----------------------------------------------------------------------------------

SAME_ATTRS = ("msm_params", "protocol", "solver")
RESIDUAL_ATTRS = ("max_residual_N", "stored_residual_N")     # merged: the largest of any shard


def merge_shards(paths: Sequence[str | Path], out: str | Path) -> dict[str, np.ndarray]:
    """Join the shard files of one run into the states file a one-process run writes."""
    if not paths:
        raise BadInput(None, "--merge needs the shard files")
    shards: dict[int, Path] = {}
    first: dict | None = None
    count = None
    for path in map(Path, paths):
        validate_states(path)
        with h5py.File(path, "r") as f:
            attrs = {k: attr_text(f.attrs.get(k, "")) for k in (*SAME_ATTRS, "shard", "source")}
        if attrs["source"] != "msm" or not attrs["shard"]:
            raise BadInput(path, "not an MSM shard (no 'shard' attribute from simulate --shard)")
        i, n = parse_shard(attrs["shard"])
        if first is None:
            first, count = attrs, n
        for key in SAME_ATTRS:
            if attrs[key] != first[key]:
                raise BadInput(path, f"shard of a different run: its {key} differs")
        if n != count:
            raise BadInput(path, f"shard {i}/{n} does not belong to a run of {count} shards")
        if i in shards:
            raise BadInput(path, f"shard {i}/{n} given twice (also {shards[i]})")
        shards[i] = path
    missing = sorted(set(range(count)) - set(shards))
    if missing:
        raise BadInput(None, f"shards {missing} of {count} are missing")
    parts = []
    for i in range(count):
        with h5py.File(shards[i], "r") as f:
            parts.append({name: f[name][()] for name in _dataset_names(f)})
    arrays = {}
    offset = np.cumsum([0] + [len(p["states/step"]) for p in parts[:-1]])
    for name in parts[0]:
        if name.startswith(("single/", "multi/")):        # state indices: shift per shard
            chunks = [p[name] + o for p, o in zip(parts, offset, strict=True)]
        else:
            chunks = [p[name] for p in parts]
        arrays[name] = np.concatenate(chunks).astype(parts[0][name].dtype)
    protocol = json.loads(first["protocol"])
    prov = make_provenance("simulate --merge", {"shards": count, **protocol},
                           inputs=[shards[i] for i in range(count)],
                           schema=STATES.name, schema_version=STATES.version)
    attrs = {k: v for k, v in _root_attrs(shards[0]).items()
             if k not in ("shard", "provenance", "schema", "schema_version")}
    for key in RESIDUAL_ATTRS:
        values = [_root_attrs(shards[i]).get(key) for i in range(count)]
        if all(v is not None for v in values):
            attrs[key] = float(max(values))
    attrs["provenance"] = json.dumps(prov)
    write_states(out, arrays, attrs)
    return arrays


def _dataset_names(f: h5py.File) -> list[str]:
    names: list[str] = []
    f.visititems(lambda name, obj: names.append(name) if isinstance(obj, h5py.Dataset) else None)
    return sorted(names)


def _root_attrs(path: Path) -> dict:
    with h5py.File(path, "r") as f:
        return dict(f.attrs.items())

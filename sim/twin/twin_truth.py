"""``truth.h5`` of a synthetic session (:data:`data_schema.truth.TRUTH`): what really happened.

Names, dtypes and units are the schema's; this module only says which array goes where.
The provenance is the runner's (:mod:`sim.twin.synth_stage`).
"""

from __future__ import annotations

from pathlib import Path
from typing import Any

import numpy as np

from data_schema.hdf5 import write_h5
from data_schema.truth import CLOCK_DOC, TRUTH
from sim.twin.twin import Twin

GZIP = dict.fromkeys((d.path for d in TRUTH.datasets), 1)   # the large series, fast and small


def write_truth(path: str | Path, twin: Twin, provenance: dict) -> None:
    """``truth.h5`` with its ``provenance`` (validated against the schema)."""
    write_h5(path, TRUTH, truth_arrays(twin), {"provenance": provenance, **_root_attrs(twin)},
             gzip=GZIP, track_order=True)


def truth_arrays(twin: Twin) -> dict[str, Any]:
    """Every dataset of ``truth.h5``, by path, in the order they are written."""
    m, log, st, ind = twin.mocap, twin.log, twin.states, twin.indenter
    presses = twin.hand.presses
    rate = twin.params.rate_hz
    start = np.array([np.flatnonzero(m.press == k)[0] for k in range(len(presses))])
    end = np.array([np.flatnonzero(m.press == k)[-1] for k in range(len(presses))])
    peak = np.array([int(np.ceil(p.times[4] * rate - 1e-9)) for p in presses])
    data: dict[str, Any] = {
        "point_names": [*twin.phantom.spec.markers.names, "tip"],
        "mocap/time_s": m.time_s, "mocap/points": m.points, "mocap/cluster": m.cluster,
        "mocap/body_origin": m.origin, "mocap/body_rotation": m.rotation,
        "mocap/visible": m.visible, "mocap/press": m.press,
        "force/magnitude": m.force, "force/lab": m.force_lab, "force/sensor": m.force_sensor,
        "force/torque_sensor": m.torque_sensor,
        "logger/time_s": log.time_s, "logger/mocap_time_s": log.mocap_time_s,
        "logger/force": log.force, "logger/torque": log.torque,
        "logger/tool_force": log.tool_force,
        "clock/offset_s": log.offset_s, "clock/drift_ppm": log.drift_ppm,
        "calibration/matrix": twin.sensor.calibration.matrix,
        "calibration/bias": twin.sensor.bias, "calibration/bias_drift": twin.sensor.bias_drift,
        "calibration/quantum": twin.sensor.quantum, "calibration/noise": twin.sensor.noise,
        "indenter/markers": ind.markers, "indenter/tip": ind.tip, "indenter/sensor": ind.sensor,
        "indenter/marker_names": list(ind.names),
        "phantom/to_lab": twin.to_lab, "phantom/rest_points": m.points[0, :-1],
        **region_arrays(twin),
        "locations/contact": twin.contacts, "locations/node": twin.nodes,
        "presses/location": [p.location for p in presses],
        "presses/repeat": [p.repeat for p in presses],
        "presses/direction": np.array([p.direction for p in presses]),
        "presses/fmax": [p.fmax for p in presses],
        "presses/start_frame": start, "presses/peak_frame": peak, "presses/end_frame": end,
        "presses/times_s": np.array([p.times for p in presses]),
        "states/points": st.points, "states/force": st.force,
        "states/force_vector": st.force_vector, "states/step": st.step,
        "states/press": st.press, "states/location": st.location, "states/time_s": st.time_s,
        "pivot/point": twin.pivot.point, "pivot/time_s": twin.pivot.time_s,
        "pivot/cluster": twin.pivot.cluster, "pivot/rotation": twin.pivot.rotation,
    }
    if twin.phantom.spec.shape is not None:
        data.update(shape_arrays(twin))
    if twin.params.trigger:
        scale = 1.0 + log.drift_ppm * 1e-6
        data["trigger/mocap_time_s"] = log.pulses
        data["trigger/logger_time_s"] = log.offset_s + scale * log.pulses
    return data


def shape_arrays(twin: Twin) -> dict[str, np.ndarray]:
    """A curved twin's truth: the shape's frame in the lab, the rest surface, each press's
    outward normal where it touched (lab), and the tip's depth along it in each frame of the
    press (NaN outside presses), from the untouched surface point."""
    ph, m, presses = twin.phantom, twin.mocap, twin.hand.presses
    normals = np.array([twin.to_lab[:3, :3] @ ph.rest_normal(tuple(twin.nodes[p.location]))
                        for p in presses])
    depth = np.full(len(m.time_s), np.nan)
    for k, press in enumerate(presses):
        at = m.press == k
        depth[at] = (twin.contacts[press.location] - m.points[at, -1]) @ normals[k]
    if ph.spec.shape is None:
        raise ValueError("shape_arrays: a flat twin has no shape")
    to_shape = ph.spec.shape.to_shape()
    return {"phantom/shape_to_lab": twin.to_lab @ np.linalg.inv(to_shape),
            "phantom/rest_surface": twin.lab(ph.rest[ph.grid[:, :, -1]]),
            "presses/normal": normals, "mocap/depth": depth}


def region_arrays(twin: Twin) -> dict[str, np.ndarray]:
    """The block's size, its inclusions (centres in the lab) and its top layer, as truth.h5
    holds them (no rows where there are none)."""
    spec = twin.phantom.spec
    inc, layer = spec.inclusions, [] if spec.layer is None else [spec.layer]
    centres = np.array([i.centre(spec.size) for i in inc]).reshape(-1, 3)
    return {"phantom/size": np.array(spec.size),
            "inclusions/centre": twin.lab(centres),
            "inclusions/footprint": np.array([(i.x, i.y) for i in inc]).reshape(-1, 2),
            "inclusions/depth": np.array([i.depth for i in inc]),
            "inclusions/radius": np.array([i.radius for i in inc]),
            "inclusions/ratio": np.array([i.ratio for i in inc]),
            "layers/thickness": np.array([y.thickness for y in layer]),
            "layers/ratio": np.array([y.ratio for y in layer])}


def _root_attrs(twin: Twin) -> dict[str, Any]:
    err = twin.params.errors
    noise = {"residual": "gamma-distributed length in a uniform random direction, independent "
                         "per sample", "mean_m": err.residual_mean, "sd_m": err.residual_sd}
    return {"seed": twin.params.seed, "rate_hz": twin.params.rate_hz,
            "logger_rate_hz": twin.params.logger_hz, "clock_convention": CLOCK_DOC,
            "units_length": "m", "units_force": "N", "units_time": "s", "noise_model": noise,
            "clock/offset_s/doc": CLOCK_DOC, "clock/drift_ppm/doc": CLOCK_DOC}


"""``states.h5``: static states and the single-/multi-step examples built from them.

One layout serves extracted lab states and MSM simulations, so trainers read both alike.
An example is a pair of state indices (start, end): input points ``points[start]``, target
``points[end]``, condition ``C = [tip[start], tip[end]]``, force change
``force[end] - force[start]``. States are grouped into sequences (one press, or one MSM
location and direction), and sequences into locations (the unit that splits keep together).
"""

from data_schema.hdf5 import Dataset, H5Schema

STATES = H5Schema(
    name="phantom.states",
    version="1.0",
    root_attrs=("provenance", "source", "units_length", "units_force"),
    doc=__doc__ or "",
    datasets=(
        Dataset("states/points", "f4", ("S", "N", 3), "m",
                doc="surface points of each static state (lab: 25 markers + tip)"),
        Dataset("states/tip", "f4", ("S", 3), "m",
                doc="indenter tip (lab) or loaded mass (MSM) position"),
        Dataset("states/force", "f4", ("S",), "N", doc="force magnitude at the state"),
        Dataset("states/force_vector", "f4", ("S", 3), "N", required=False,
                doc="force vector at the state (lab frame)"),
        Dataset("states/step", "i4", ("S",), doc="force step t (0 = unloaded, t * 0.5 N)"),
        Dataset("states/sequence", "i4", ("S",), doc="press (lab) or location x direction (MSM)"),
        Dataset("states/location", "i4", ("S",), doc="indentation location: the split group"),
        Dataset("single/start", "i4", ("E1",), doc="single-step examples: state at t"),
        Dataset("single/end", "i4", ("E1",), doc="single-step examples: state at t + 1"),
        Dataset("multi/start", "i4", ("E2",), doc="multi-step examples: state at t"),
        Dataset("multi/end", "i4", ("E2",), doc="multi-step examples: state at least 2 steps on"),
    ),
)

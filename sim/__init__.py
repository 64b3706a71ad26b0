"""The two simulators, apart: the phantom twin (:mod:`sim.twin`, ``pipeline synth``), a lab
session with its truth, and the paper's surface mass-spring model (:mod:`sim.msm`, ``pipeline
simulate`` and ``fit-msm``). They share one helper, :mod:`sim.cone` (force directions)."""

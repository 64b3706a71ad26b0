"""``pipeline synth``: the phantom twin, a synthetic lab session written as the lab writes it,
with the truth.

The math (:mod:`sim.twin.twin` and its parts: the volumetric phantom, the hand, the mocap, the
force log, the pivot trial, the true states; QTM's 6D body of its own, :mod:`sim.twin.body_fit`),
the stage runner (:mod:`sim.twin.synth_stage`) and the view (:mod:`sim.twin.synth_view`). The
twin is there to check sync and extract against known truth, so it shares none of their code.
"""

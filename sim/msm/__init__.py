"""``pipeline simulate`` and ``pipeline fit-msm``: the paper's surface mass-spring model (MSM).

The math (:mod:`sim.msm.msm` the model and its reference solver, :mod:`sim.msm.msm_static` the
fast static path, :mod:`sim.msm.msm_sampling` the MSM at a lab's markers, the data-generation
protocol and data set, the fit), the paper's constants (:mod:`sim.msm.paper`), the stage
runners (:mod:`sim.msm.simulate_stage`, :mod:`sim.msm.fit_msm_stage`) and their views
(:mod:`sim.msm.simulate_view`, :mod:`sim.msm.fit_msm_view`).
"""

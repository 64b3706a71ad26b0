"""The indentation protocol's numbers that lab stages and simulators share, each stated once.

- :data:`STEP_N`: static states every 0.5 N. The paper extracts its lab states at every 0.5 N
  and loads the MSM to 7.5 N in 15 equal steps of it; extract's ``--step`` default, the twin's
  true states and the MSM protocol all take it from here. A states file records the spacing it
  was made with (root attribute ``step_n``), so a reader computes a state's force level as
  ``step * step_n`` from the file, never from this constant.
- :data:`FOOTPRINT_M`: the phantom's footprint in the phantom frame by default, 100 x 100 mm
  (the paper's phantom, the MSM's grid): extract centres the marker grid on it.
- :data:`THICKNESS_M`: the phantom's thickness, 32 mm (the twin's block): a surface pressed
  deeper than this went through the phantom (simulate counts the MSM's states beyond it).

Plain numbers, no imports: command-line defaults read them without loading a stage.
"""

STEP_N = 0.5                     # N between force levels
FOOTPRINT_M = (0.1, 0.1)         # m, width and length of the phantom's footprint
THICKNESS_M = 0.032              # m, the phantom block's thickness

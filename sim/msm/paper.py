"""The MSM's numbers, each stated once: the paper's model and data-generation protocol, and
the tolerance our static solver works to.

The paper (section "Data generation"): a 100 x 100 mm surface of 32 x 32 masses of
0.00016 kg, damping 0.1, springs of 100 N/m between masses and 21 N/m to the rest positions,
integrated explicitly with a time step of 1e-4 s until every mass moves slower than 0.02 m/s
under less than 0.02 N; 100 locations x 11 force directions (the normal and 10 within 45
degrees) x 15 equal steps of 0.5 N (:data:`core.protocol.STEP_N`) up to 7.5 N.

Plain numbers: the command line reads its defaults here without loading the model.
"""

from core.protocol import STEP_N

# the model
GRID_N = 32                  # masses per side
SIZE_M = 0.1                 # side of the surface
MASS_KG = 0.00016            # each mass
DAMPING = 0.1                # N s/m, the damping force -c v on each mass
K_BETWEEN = 100.0            # N/m, springs between neighbouring masses
K_FIXED = 21.0               # N/m, zero-length springs to the rest positions
DT_S = 1e-4                  # explicit time step of the reference solver
V_STATIC = 0.02              # m/s: static when every mass is slower ...
F_STATIC = 0.02              # N: ... and every mass's net force is smaller

# the protocol
LOCATIONS = 100              # loaded masses, drawn at random
DIRECTIONS = 11              # per location: the normal and 10 random ones
MAX_ANGLE_DEG = 45.0         # the random directions' largest angle from the normal
STEPS = 15                   # equal force steps ...
FMAX_N = STEPS * STEP_N      # ... up to 7.5 N

# ours, not the paper's (it integrated explicitly): the static path's tolerance
STATIC_TOL_N = 1e-6          # the largest force left on any mass at an accepted equilibrium

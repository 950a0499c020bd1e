"""The packed coefficient table and the per-contact history: their column layout.

Every contact kernel takes one table ``coefficients[a, b, column]`` (float64) indexed by the two
rows (materials, or a solid's contact surface) of a contact, instead of one array per constant.
The common columns come first; each sub-model kind then owns a small block of parameters that
its model reads in its own way (a new model of a kind needs no new column).  Model codes are
stored as floats (small integers, exact).

A contact's history (tangential spring, rolling spring, cohesive "touching" flag) is one row of
``HISTORY`` columns whose layout depends on the *composition*: the bit set of the sub-models a
scene uses, passed to the kernels with the table (a branch per sub-model, never taken when unused), so a scene
without friction carries no tangential spring and runs no tangential code.
"""
from __future__ import annotations

# ---- columns of the packed table
EFFECTIVE_MODULUS = 0        # E* [Pa]
EFFECTIVE_SHEAR_MODULUS = 1  # G* [Pa]
NORMAL_MODEL = 2             # registry code of the normal model
DAMPING = 3                  # gamma: dashpot gamma sqrt(m* S), calibrated to the restitution
FRICTION = 4                 # mu (Coulomb)
ROLLING_MODEL = 5            # registry code of the rolling model (0: none)
ROLLING_FRICTION = 6         # mu_r: rolling torque limit mu_r R* F_n
COHESION_REACH = 7           # largest distance [m] beyond touching at which the pair still interacts
NORMAL_PARAMETERS = 8        # first of NORMAL_PARAMETER_COUNT columns owned by the normal model
NORMAL_PARAMETER_COUNT = 4
ROLLING_PARAMETERS = NORMAL_PARAMETERS + NORMAL_PARAMETER_COUNT
ROLLING_PARAMETER_COUNT = 2
CONTACT_CONDUCTIVITY = ROLLING_PARAMETERS + ROLLING_PARAMETER_COUNT  # k* = 2 k_a k_b / (k_a + k_b) [W/(m K)]
COLUMNS = CONTACT_CONDUCTIVITY + 1

# ---- composition bits (which sub-models a scene's kernels are compiled with)
NORMAL_BITS = 0          # bit NORMAL_BITS + code: that normal model is used by some pair
MAXIMUM_NORMAL_MODELS = 8
TANGENTIAL = 1 << 8      # some pair has friction: tangential spring history and force
ROLLING_BITS = 9         # bit ROLLING_BITS + code - 1: that rolling model is used (code 0 = none)
MAXIMUM_ROLLING_MODELS = 4
ROLLING_ANY = ((1 << MAXIMUM_ROLLING_MODELS) - 1) << ROLLING_BITS
COHESIVE = 1 << 13       # some normal model in use attracts beyond touching: a "touching" flag per contact
HEAT = 1 << 14           # heat is on: contacts conduct (pdemfem.contact.conduction), no history needed

# ---- history columns (the order is fixed; a block is present only when its bit is set;
#      pdemfem.contact.registry.history_layout)
TANGENTIAL_COLUMNS = 6   # xi: the tangential spring's displacement, then the tangential force applied at the last
                         # evaluation (both flip sign with the pair's order)
ROLLING_APPLIED_COLUMNS = 3  # the rolling moment applied at the last evaluation (flips sign); every rolling model
ROLLING_SPRING_COLUMNS = 3   # then a rolling spring's moment on the first particle (flips sign), for models with one
SPRING_ENERGY_COLUMNS = 1  # the springs' energy as booked at the last evaluation (symmetric)
COHESIVE_COLUMNS = 1     # 1.0 while the contact is formed (symmetric)


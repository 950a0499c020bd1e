"""The contact sub-models: one registration table, and the dispatchers the kernels call.

A sub-model is a module with a NAME, a CODE (its row in the packed table) and jitted functions
of its kind's signature (see the modules).  Kinds:

- normal (`NORMAL_MODELS`): elastic(overlap, coefficients, a, b, m*, R*) -> (F, S_n, S_t, energy),
  pull_off_overlap(...) -> the overlap at which a formed contact breaks (0 or negative),
  friction_offset(...) -> the load added to F_n in the Coulomb limit, conduction_radius(overlap, ...) -> the
  radius of the contact area heat flows through (pdemfem.contact.conduction); and on the host
  parameters(interaction, E*, v) -> its parameter block, pull_off_distance(...), COHESIVE,
  DAMPING_LAW (which restitution calibration its dashpot uses);
- tangential: `tangential_mindlin` (the only one; used when some pair has friction);
- damping: `damping_viscous`;
- rolling (`ROLLING_MODELS`): torque(...) -> (moment (3), spring energy, work taken from the motion
  minus that energy), HISTORY_COLUMNS.

The interaction key `model` names a normal model; `rolling_model` a rolling model.  To add a
model: write its module and add it to the list of its kind below (docs/contact_models.md).

Dispatch.  The kernels get a *composition* (pdemfem.contact.layout): the set of models a scene
uses.  `normal_elastic` and friends test, model by model, the composition bit first (the same on
every contact: a predicted branch) and then the
pair's code from the table; the last model in use takes every remaining code, so a scene with
one normal model pays no test at all.
"""
from __future__ import annotations

from numba import njit

from pdemfem.contact import (normal_hertz, normal_jkr, normal_linear, rolling_constant_torque,
                             rolling_elastic_plastic)
from pdemfem.contact.layout import (COHESIVE, COHESIVE_COLUMNS, MAXIMUM_NORMAL_MODELS, MAXIMUM_ROLLING_MODELS,
                                    NORMAL_BITS, ROLLING_APPLIED_COLUMNS, ROLLING_BITS, ROLLING_SPRING_COLUMNS,
                                    SPRING_ENERGY_COLUMNS, TANGENTIAL,
                                    TANGENTIAL_COLUMNS)

NORMAL_MODELS = (
    normal_hertz,
    normal_linear,
    normal_jkr,
)
ROLLING_MODELS = (
    rolling_constant_torque,
    rolling_elastic_plastic,
)

NORMAL_BY_NAME = {model.NAME: model for model in NORMAL_MODELS}
ROLLING_BY_NAME = {model.NAME: model for model in ROLLING_MODELS}
assert len(NORMAL_MODELS) <= MAXIMUM_NORMAL_MODELS and len(ROLLING_MODELS) <= MAXIMUM_ROLLING_MODELS
assert sorted(model.CODE for model in NORMAL_MODELS) == list(range(len(NORMAL_MODELS)))
assert sorted(model.CODE for model in ROLLING_MODELS) == list(range(1, len(ROLLING_MODELS) + 1))


def damping_law(model_name: str) -> str:
    """The restitution calibration ('hertz_mindlin' or 'linear_spring_dashpot') a normal model's dashpot uses."""
    return NORMAL_BY_NAME[model_name].DAMPING_LAW


def normal_bit(model) -> int:
    return 1 << (NORMAL_BITS + model.CODE)


def rolling_bit(model) -> int:
    return 1 << (ROLLING_BITS + model.CODE - 1)


# Rolling models that keep a history (the moment applied at the last evaluation, for the books), and those
# that keep a spring after it.
ROLLING_HISTORY_BITS = sum(rolling_bit(model) for model in ROLLING_MODELS if model.HISTORY_COLUMNS)
ROLLING_SPRING_BITS = sum(rolling_bit(model) for model in ROLLING_MODELS
                          if model.HISTORY_COLUMNS > ROLLING_APPLIED_COLUMNS)
assert all(model.HISTORY_COLUMNS in (ROLLING_APPLIED_COLUMNS, ROLLING_APPLIED_COLUMNS + ROLLING_SPRING_COLUMNS)
           for model in ROLLING_MODELS)


@njit(inline="always", cache=True)
def _rolling_columns(composition):
    if composition & ROLLING_SPRING_BITS:
        return ROLLING_APPLIED_COLUMNS + ROLLING_SPRING_COLUMNS
    if composition & ROLLING_HISTORY_BITS:
        return ROLLING_APPLIED_COLUMNS
    return 0


@njit(inline="always", cache=True)
def history_layout(composition):
    """(tangential column, rolling column, touching column, width) of a contact's history; -1: absent.
    With springs, the column after them holds their energy as booked (`spring_energy_column`)."""
    column = 0
    tangential = -1
    rolling = -1
    touching = -1
    if composition & TANGENTIAL:
        tangential = column
        column += TANGENTIAL_COLUMNS
    if composition & ROLLING_HISTORY_BITS:
        rolling = column
        column += _rolling_columns(composition)
    if tangential >= 0 or rolling >= 0:
        column += SPRING_ENERGY_COLUMNS
    if composition & COHESIVE:
        touching = column
        column += COHESIVE_COLUMNS
    return tangential, rolling, touching, column


@njit(inline="always", cache=True)
def spring_energy_column(composition):
    """The column holding the energy the contact's springs were booked with at its last evaluation (-1: no
    springs).  The next evaluation books the springs' energy change against it, and an opening contact
    loses it, with no stiffness recomputed at the previous overlap."""
    column = 0
    if composition & TANGENTIAL:
        column += TANGENTIAL_COLUMNS
    column += _rolling_columns(composition)
    return column - 1 + SPRING_ENERGY_COLUMNS if column > 0 else -1


def history_signs(composition: int) -> tuple:
    """+1/-1 per history column: how it changes when the pair is seen from the other body (the
    springs flip; their energy and the touching flag do not)."""
    tangential, rolling, touching, width = history_layout(composition)
    energy = spring_energy_column(composition)
    return tuple(1.0 if column in (touching, energy) else -1.0 for column in range(width))


# ------------------------------------------------------------------ dispatch chains
def _later_mask(models, index, bit) -> int:
    return sum(bit(model) for model in models[index + 1:])


def _normal_chain(models, index, function_name, zero):
    """Jitted dispatcher over models[index:] of the normal function `function_name`."""
    if index == len(models):
        @njit(inline="always")
        def none_left(model, composition, overlap, coefficients, a, b, effective_mass, effective_radius):
            return zero
        return none_left
    function = getattr(models[index], function_name)
    code = models[index].CODE
    own_bit = normal_bit(models[index])
    later = _later_mask(models, index, normal_bit)
    rest = _normal_chain(models, index + 1, function_name, zero)

    @njit(inline="always")
    def link(model, composition, overlap, coefficients, a, b, effective_mass, effective_radius):
        if composition & own_bit:
            if model == code or (composition & later) == 0:
                return function(overlap, coefficients, a, b, effective_mass, effective_radius)
        return rest(model, composition, overlap, coefficients, a, b, effective_mass, effective_radius)
    return link


def _pair_constant_chain(models, index, function_name):
    """Like _normal_chain for the functions of (coefficients, a, b, R*) -> float.  (One generic chain with
    *arguments would serve all three, but numba's IR inlining does not take star arguments.)"""
    if index == len(models):
        @njit(inline="always")
        def none_left(model, composition, coefficients, a, b, effective_radius):
            return 0.0
        return none_left
    function = getattr(models[index], function_name)
    code = models[index].CODE
    own_bit = normal_bit(models[index])
    later = _later_mask(models, index, normal_bit)
    rest = _pair_constant_chain(models, index + 1, function_name)

    @njit(inline="always")
    def link(model, composition, coefficients, a, b, effective_radius):
        if composition & own_bit:
            if model == code or (composition & later) == 0:
                return function(coefficients, a, b, effective_radius)
        return rest(model, composition, coefficients, a, b, effective_radius)
    return link


def _rolling_chain(models, index):
    if index == len(models):
        @njit(inline="always")
        def none_left(model, composition, coefficients, a, b, nx, ny, nz, wx, wy, wz, normal_force,
                      normal_stiffness, effective_radius, effective_inertia, rolling_inertia, history,
                      row, column, dt):
            return 0.0, 0.0, 0.0, 0.0, 0.0
        return none_left
    function = models[index].torque
    code = models[index].CODE
    own_bit = rolling_bit(models[index])
    rest = _rolling_chain(models, index + 1)

    @njit(inline="always")
    def link(model, composition, coefficients, a, b, nx, ny, nz, wx, wy, wz, normal_force, normal_stiffness,
             effective_radius, effective_inertia, rolling_inertia, history, row, column, dt):
        # Code 0 (no rolling resistance) never matches: a pair without it gets no torque.
        if composition & own_bit:
            if model == code:
                return function(coefficients, a, b, nx, ny, nz, wx, wy, wz, normal_force, normal_stiffness,
                                effective_radius, effective_inertia, rolling_inertia, history, row,
                                column, dt)
        return rest(model, composition, coefficients, a, b, nx, ny, nz, wx, wy, wz, normal_force, normal_stiffness,
                    effective_radius, effective_inertia, rolling_inertia, history, row, column, dt)
    return link


normal_elastic = _normal_chain(NORMAL_MODELS, 0, "elastic", (0.0, 0.0, 0.0, 0.0))
normal_conduction_radius = _normal_chain(NORMAL_MODELS, 0, "conduction_radius", 0.0)
normal_pull_off_overlap = _pair_constant_chain(NORMAL_MODELS, 0, "pull_off_overlap")
normal_friction_offset = _pair_constant_chain(NORMAL_MODELS, 0, "friction_offset")
rolling_torque = _rolling_chain(ROLLING_MODELS, 0)

"""Normal model `linear_spring_dashpot`: a linear spring k_n (tangential k_t = ratio k_n).

When the interaction gives no `normal_stiffness`, k_n is derived per contact so that the peak
overlap of an elastic impact at the characteristic speed v equals Hertz's:
delta_max = (15 m* v^2 / (16 E* sqrt(R*)))^(2/5), k_n = m* v^2 / delta_max^2.
"""
from __future__ import annotations

import math

from numba import njit

from pdemfem.contact.geometry import no_pull_off
from pdemfem.contact.layout import EFFECTIVE_MODULUS, NORMAL_PARAMETERS
from pdemfem.errors import SceneError

NAME = "linear_spring_dashpot"
CODE = 1
COHESIVE = False
DAMPING_LAW = "linear_spring_dashpot"

STIFFNESS = NORMAL_PARAMETERS            # k_n [N/m]; 0: derive per contact
TANGENTIAL_RATIO = NORMAL_PARAMETERS + 1  # k_t / k_n
CHARACTERISTIC_SPEED = NORMAL_PARAMETERS + 2  # v [m/s] of the derived stiffness


def parameters(interaction, effective_modulus: float, characteristic_speed: float) -> tuple:
    if not interaction.normal_stiffness and not characteristic_speed > 0.0:
        # k_n = m* v^2 / delta_max^2 goes to 0 with v: the contact would have no stiffness at all.
        raise SceneError("interactions (model linear_spring_dashpot)",
                         "the spring's stiffness is derived from the expected impact speed, and this scene has none "
                         "(no initial velocities, no moving walls, nothing above a wall to fall): it would be 0",
                         "give the interaction a normal_stiffness [N/m], or set time.expected_impact_speed [m/s]")
    return (interaction.normal_stiffness or 0.0, interaction.tangential_stiffness_ratio, characteristic_speed)


def pull_off_distance(parameters_row, effective_modulus: float, effective_radius: float) -> float:
    return 0.0


@njit(inline="always", cache=True)
def elastic(overlap, coefficients, a, b, effective_mass, effective_radius):
    stiffness = coefficients[a, b, STIFFNESS]
    if stiffness <= 0.0:
        speed_squared = coefficients[a, b, CHARACTERISTIC_SPEED] ** 2
        peak_overlap = (15.0 * effective_mass * speed_squared
                        / (16.0 * coefficients[a, b, EFFECTIVE_MODULUS] * math.sqrt(effective_radius))) ** 0.4
        stiffness = effective_mass * speed_squared / (peak_overlap * peak_overlap)
    return (stiffness * overlap, stiffness, coefficients[a, b, TANGENTIAL_RATIO] * stiffness,
            0.5 * stiffness * overlap * overlap)


@njit(inline="always", cache=True)
def conduction_radius(overlap, coefficients, a, b, effective_mass, effective_radius):
    """The radius of the contact area heat flows through: Hertz's a = sqrt(R* delta)."""
    return math.sqrt(effective_radius * overlap) if overlap > 0.0 else 0.0


# Not cohesive: a contact opens at zero overlap and friction sees F_n alone.
pull_off_overlap = no_pull_off
friction_offset = no_pull_off

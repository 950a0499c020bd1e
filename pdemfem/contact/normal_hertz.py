"""Normal model `hertz_mindlin`: Hertz's elastic sphere contact, with Mindlin's tangential stiffness.

    a = sqrt(R* delta),  F = 4/3 E* a delta,  S_n = dF/ddelta = 2 E* a,  S_t = 8 G* a,
    energy 8/15 E* sqrt(R*) delta^(5/2) = 2/5 F delta.

Reference: K. L. Johnson, Contact Mechanics (1985), ch. 4 and 7.
"""
from __future__ import annotations

import math

from numba import njit

from pdemfem.contact.geometry import no_pull_off
from pdemfem.contact.layout import EFFECTIVE_MODULUS, EFFECTIVE_SHEAR_MODULUS

NAME = "hertz_mindlin"
CODE = 0
COHESIVE = False
DAMPING_LAW = "hertz_mindlin"   # the restitution calibration this law's dashpot uses


def parameters(interaction, effective_modulus: float, characteristic_speed: float) -> tuple:
    """The model's parameter block of the packed table (none)."""
    return ()


def pull_off_distance(parameters_row, effective_modulus: float, effective_radius: float) -> float:
    return 0.0


@njit(inline="always", cache=True)
def elastic(overlap, coefficients, a, b, effective_mass, effective_radius):
    """(elastic force, S_n, S_t, elastic energy) at `overlap` > 0."""
    contact_radius = math.sqrt(effective_radius * overlap)
    modulus = coefficients[a, b, EFFECTIVE_MODULUS]
    force = (4.0 / 3.0) * modulus * contact_radius * overlap
    return (force, 2.0 * modulus * contact_radius, 8.0 * coefficients[a, b, EFFECTIVE_SHEAR_MODULUS] * contact_radius,
            0.4 * force * overlap)


@njit(inline="always", cache=True)
def conduction_radius(overlap, coefficients, a, b, effective_mass, effective_radius):
    """The radius of the contact area heat flows through: Hertz's a = sqrt(R* delta)."""
    return math.sqrt(effective_radius * overlap) if overlap > 0.0 else 0.0


# Not cohesive: a contact opens at zero overlap and friction sees F_n alone.
pull_off_overlap = no_pull_off
friction_offset = no_pull_off

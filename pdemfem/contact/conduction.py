"""Heat conduction through a contact: Batchelor & O'Brien's contact-area conductance.

Two smooth spheres pressed together conduct heat through their contact circle of radius a.
Each body's spreading resistance from a circle of radius a into a half-space is 1 / (4 k a);
the two in series give the conductance

    H = 4 a k_a k_b / (k_a + k_b) = 2 k* a,     k* = 2 k_a k_b / (k_a + k_b)

(k* = k for one material), and the heat flow into body i is Q_i = H (T_j - T_i).
Reference: G. K. Batchelor & R. W. O'Brien, Thermal or electrical conduction through a
granular material, Proc. R. Soc. A 355 (1977) 313-333 (their eq. for touching spheres
with a conducting contact circle); the same law as LIGGGHTS' heat/gran/conduction.

a comes from the pair's normal model (`conduction_radius`: Hertz's sqrt(R* delta) for
hertz_mindlin and linear_spring_dashpot, the JKR radius for jkr), so a wall or a solid's
surface (R = inf) uses R* = the particle's radius.  Assumptions (docs/heat.md): each
particle is isothermal (the contact's Biot number H / (k R) ~ a / R is small), the
interstitial gas and radiation carry nothing, and the contact holds no thermal history.
"""
from __future__ import annotations

from numba import njit

from pdemfem.contact.layout import CONTACT_CONDUCTIVITY, NORMAL_MODEL
from pdemfem.contact.registry import normal_conduction_radius

NAME = "batchelor_obrien"


def pair_conductivity(conductivity_a, conductivity_b) -> float:
    """k* of a pair [W/(m K)]: 0 when one body is adiabatic (no conductivity)."""
    if not conductivity_a or not conductivity_b:
        return 0.0
    return 2.0 * conductivity_a * conductivity_b / (conductivity_a + conductivity_b)


@njit(inline="always", cache=True)
def contact_conductance(composition, coefficients, a, b, overlap, effective_mass, effective_radius):
    """H = 2 k* a [W/K] of one contact at `overlap` (cohesive contacts: down to their pull-off overlap)."""
    radius = normal_conduction_radius(int(coefficients[a, b, NORMAL_MODEL]), composition, overlap, coefficients, a,
                                      b, effective_mass, effective_radius)
    return 2.0 * coefficients[a, b, CONTACT_CONDUCTIVITY] * radius

"""Normal model `jkr`: Johnson-Kendall-Roberts adhesive elastic contact (work of adhesion W).

Contact radius a and overlap delta, with E* and R* of the pair (Johnson, Kendall & Roberts,
Proc. R. Soc. A 324 (1971); Johnson, Contact Mechanics (1985) sec. 5.5):

    delta = a^2 / R* - sqrt(2 pi W a / E*),      F = 4 E* a^3 / (3 R*) - sqrt(8 pi W E* a^3)

(F > 0 pushes the spheres apart).  At zero load a0^3 = 9 pi W R*^2 / (2 E*) and
delta0 = a0^2 / (3 R*); under load control the contact comes off at F = -3/2 pi W R*.
A contact forms when the spheres touch (delta = 0, where a jumps to (R* sqrt(2 pi W / E*))^(2/3))
and, once formed, holds until delta reaches the displacement-control limit
delta_c = -3 a_c^2 / R*, a_c^3 = pi W R*^2 / (8 E*) (the stable branch ends there).

Given delta, a is the largest root of the quartic s^4 - C R* s - delta R* = 0 in s = sqrt(a)
(C = sqrt(2 pi W / E*)), solved in closed form (Ferrari, with the resolvent cubic
m^3 + delta R* m - C^2 R*^2 / 8 = 0 solved by Cardano without cancellation), no iteration.

Elastic energy: the potential Phi(delta) = integral of F ddelta from delta = 0 along the branch,
    U(a) = 2 A a^5 / (5 R*) - (A C / 7 + 4 B / (7 R*)) a^(7/2) + B C a^2 / 4,
    A = 4 E* / (3 R*), B = sqrt(8 pi W E*),   Phi = U(a(delta)) - U(a(0)),
so no energy jumps when a contact forms; what a contact holds when it breaks at delta_c
(Phi(delta_c) > 0: the adhesion hysteresis) is booked as dissipated.

Damping and friction: the dashpot gamma sqrt(m* S_n) with S_n = 2 E* a (the Hertz stiffness at
the same contact radius, and gamma from the Hertz restitution calibration); Mindlin's
S_t = 8 G* a; the Coulomb limit counts the adhesive load, mu (F_n + 2 F_c) with
F_c = 3/2 pi W R* (Thornton & Yin, Powder Technol. 65 (1991)).
"""
from __future__ import annotations

import math

from numba import njit

from pdemfem.contact.layout import EFFECTIVE_MODULUS, EFFECTIVE_SHEAR_MODULUS, NORMAL_PARAMETERS

NAME = "jkr"
CODE = 2
COHESIVE = True
DAMPING_LAW = "hertz_mindlin"

WORK_OF_ADHESION = NORMAL_PARAMETERS  # W [J/m^2]


def parameters(interaction, effective_modulus: float, characteristic_speed: float) -> tuple:
    return (interaction.work_of_adhesion,)


def pull_off_distance(parameters_row, effective_modulus: float, effective_radius: float) -> float:
    """|delta_c| for R* = effective_radius (it grows with R*^(1/3): an upper bound for smaller pairs)."""
    work = parameters_row[0]
    return 3.0 * (math.pi * work * effective_radius ** 2 / (8.0 * effective_modulus)) ** (2.0 / 3.0) / effective_radius


@njit(inline="always", cache=True)
def contact_radius(overlap, work, modulus, radius):
    """a(delta) on the stable branch (module docstring); valid for delta >= delta_c."""
    c = math.sqrt(2.0 * math.pi * work / modulus)
    p = overlap * radius
    q = -0.125 * c * c * radius * radius
    discriminant = 0.25 * q * q + p * p * p / 27.0
    if discriminant >= 0.0:
        u = (-0.5 * q + math.sqrt(discriminant)) ** (1.0 / 3.0)
        m = u - p / (3.0 * u)
    else:
        # Three real roots (p < 0): the largest.
        ratio = 1.5 * q / p * math.sqrt(-3.0 / p)
        ratio = min(1.0, max(-1.0, ratio))
        m = 2.0 * math.sqrt(-p / 3.0) * math.cos(math.acos(ratio) / 3.0)
    root = math.sqrt(2.0 * m)
    s = 0.5 * (root + math.sqrt(max(0.0, -2.0 * m + 2.0 * c * radius / root)))
    return s * s


@njit(inline="always", cache=True)
def _potential(a, work, modulus, radius):
    big_a = 4.0 * modulus / (3.0 * radius)
    big_b = math.sqrt(8.0 * math.pi * work * modulus)
    c = math.sqrt(2.0 * math.pi * work / modulus)
    return (0.4 * big_a * a ** 5 / radius - (big_a * c / 7.0 + 4.0 * big_b / (7.0 * radius)) * a ** 3.5
            + 0.25 * big_b * c * a * a)


@njit(inline="always", cache=True)
def elastic(overlap, coefficients, a, b, effective_mass, effective_radius):
    work = coefficients[a, b, WORK_OF_ADHESION]
    modulus = coefficients[a, b, EFFECTIVE_MODULUS]
    radius = contact_radius(overlap, work, modulus, effective_radius)
    force = 4.0 * modulus * radius ** 3 / (3.0 * effective_radius) - math.sqrt(8.0 * math.pi * work * modulus * radius ** 3)
    touching_radius = (effective_radius * math.sqrt(2.0 * math.pi * work / modulus)) ** (2.0 / 3.0)
    energy = (_potential(radius, work, modulus, effective_radius)
              - _potential(touching_radius, work, modulus, effective_radius))
    return (force, 2.0 * modulus * radius, 8.0 * coefficients[a, b, EFFECTIVE_SHEAR_MODULUS] * radius, energy)


@njit(inline="always", cache=True)
def conduction_radius(overlap, coefficients, a, b, effective_mass, effective_radius):
    """The radius of the contact area heat flows through: the JKR a(delta) (finite down to delta_c)."""
    return contact_radius(overlap, coefficients[a, b, WORK_OF_ADHESION], coefficients[a, b, EFFECTIVE_MODULUS],
                          effective_radius)


@njit(inline="always", cache=True)
def pull_off_overlap(coefficients, a, b, effective_radius):
    work = coefficients[a, b, WORK_OF_ADHESION]
    modulus = coefficients[a, b, EFFECTIVE_MODULUS]
    return -3.0 * (math.pi * work * effective_radius ** 2 / (8.0 * modulus)) ** (2.0 / 3.0) / effective_radius


@njit(inline="always", cache=True)
def friction_offset(coefficients, a, b, effective_radius):
    return 3.0 * math.pi * coefficients[a, b, WORK_OF_ADHESION] * effective_radius

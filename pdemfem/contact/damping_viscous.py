"""Damping model `viscous`: dashpots gamma sqrt(m* S) on the normal and tangential motion.

gamma is calibrated once per interaction so that a head-on impact rebounds with the asked
`restitution` exactly for the clamped force law of the normal model's damping law (see
pdemfem.contact.restitution and docs/restitution.md); with S_n the normal model's stiffness
it needs no per-contact iteration.
"""
from __future__ import annotations

import math

from numba import njit

from pdemfem.contact.restitution import normal_damping_coefficient

NAME = "viscous"


def coefficient(damping_law: str, restitution: float) -> float:
    return normal_damping_coefficient(damping_law, restitution)


@njit(inline="always", cache=True)
def dashpot(gamma, effective_mass, stiffness):
    return gamma * math.sqrt(effective_mass * stiffness)

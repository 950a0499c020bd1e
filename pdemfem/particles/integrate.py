"""Velocity Verlet for spheres: half kick, drift, (forces), half kick — owned rows only."""
from __future__ import annotations

import numpy as np
from numba import njit


@njit(cache=True)
def kick(owned_count, velocities, angular_velocities, forces, torques, inverse_mass, inverse_inertia, gravity,
         half_dt):
    """v += dt/2 (F/m + g); w += dt/2 T/I."""
    for i in range(owned_count):
        for axis in range(3):
            velocities[i, axis] += half_dt * (forces[i, axis] * inverse_mass[i] + gravity[axis])
            angular_velocities[i, axis] += half_dt * torques[i, axis] * inverse_inertia[i]


@njit(cache=True)
def drift(owned_count, positions, velocities, dt, positions_at_build):
    """x += dt v; returns the largest squared displacement since the last list build.

    A non-finite position (a blown-up particle) returns inf, so the caller rebuilds at
    once and the rebuild removes the particle before its NaN reaches the contact kernels
    (a plain maximum would skip NaN).
    """
    largest = 0.0
    for i in range(owned_count):
        displacement_squared = 0.0
        for axis in range(3):
            positions[i, axis] += dt * velocities[i, axis]
            offset = positions[i, axis] - positions_at_build[i, axis]
            displacement_squared += offset * offset
        if not displacement_squared < np.inf:
            largest = np.inf
        elif displacement_squared > largest:
            largest = displacement_squared
    return largest

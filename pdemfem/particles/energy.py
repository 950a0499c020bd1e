"""Energy sums over the owned particles in one pass (history rows and the run monitor)."""
from __future__ import annotations

import numpy as np
from numba import njit


@njit(cache=True)
def particle_energy_sums(owned_count, mass, velocities, angular_velocities, inverse_inertia, positions, gravity):
    """(kinetic, rotational, gravitational potential -m g.x, largest squared speed) of rows [0, owned_count).

    A non-finite velocity makes the largest squared speed inf (a plain maximum would skip NaN)."""
    kinetic = 0.0
    rotational = 0.0
    potential = 0.0
    fastest = 0.0
    for i in range(owned_count):
        speed_squared = 0.0
        spin_squared = 0.0
        height = 0.0
        for axis in range(3):
            speed_squared += velocities[i, axis] * velocities[i, axis]
            spin_squared += angular_velocities[i, axis] * angular_velocities[i, axis]
            height += positions[i, axis] * gravity[axis]
        kinetic += mass[i] * speed_squared
        rotational += spin_squared / inverse_inertia[i]
        potential -= mass[i] * height
        if speed_squared > fastest:
            fastest = speed_squared
        elif speed_squared != speed_squared:  # NaN
            fastest = np.inf
    return 0.5 * kinetic, 0.5 * rotational, potential, fastest

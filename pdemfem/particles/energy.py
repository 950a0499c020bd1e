"""Energy sums over the owned particles in one pass (history rows and the run monitor)."""
from __future__ import annotations

import numpy as np
from numba import njit


# Every row is a single sphere (no clumps): what particle_energy_sums takes as clump_body then.
NO_CLUMP_BODIES = np.empty(0, dtype=np.int64)


@njit(cache=True)
def particle_energy_sums(owned_count, mass, velocities, angular_velocities, inverse_inertia, positions, gravity,
                         clump_body):
    """(kinetic, rotational, gravitational potential -m g.x, largest squared speed) of rows [0, owned_count).

    Rows with clump_body[i] >= 0 are members of a rigid clump, whose energies are counted with its body
    (pdemfem.clumps.bodies): they are left out of the sums, not of the largest speed.  An empty clump_body
    (NO_CLUMP_BODIES): every row is a sphere.  A non-finite velocity makes the largest squared speed inf
    (a plain maximum would skip NaN)."""
    every_row = clump_body.shape[0] == 0
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
        if every_row or clump_body[i] < 0:
            kinetic += mass[i] * speed_squared
            rotational += spin_squared / inverse_inertia[i]
            potential -= mass[i] * height
        if speed_squared > fastest:
            fastest = speed_squared
        elif speed_squared != speed_squared:  # NaN
            fastest = np.inf
    return 0.5 * kinetic, 0.5 * rotational, potential, fastest


def energy_leaving(state, rows: np.ndarray, gravity, half_dt: float) -> float:
    """Kinetic + rotational + potential energy [J] of the owned `rows` (free spheres) at the end of the step in
    which a list rebuild removes them (domain box, outlets).  The rebuild comes between the drift and the force
    evaluation, so their velocities are the half step's: the second half kick is completed here with gravity
    (exact in free flight; booked at the half step, 25 spheres falling out of a box moved the total by 1.4e-4 of
    their energy).  The step's contact forces are not known yet (the drift zeroed the rows' loads): a particle
    taken while it touches others books O(dt F v) off, as it leaves its contacts' elastic energy.  Rows with a
    non-finite state are left out: that is a divergence, which the run monitor reports."""
    rows = np.asarray(rows, dtype=np.int64)
    if not len(rows):
        return 0.0
    gravity = np.asarray(gravity, dtype=float)
    velocities = state.velocities[rows] + half_dt * gravity
    spins = state.angular_velocities[rows]
    positions = state.positions[rows]
    finite = np.isfinite(positions).all(axis=1) & np.isfinite(velocities).all(axis=1) & np.isfinite(spins).all(axis=1)
    kinetic, rotational, potential, _ = particle_energy_sums(
        int(np.count_nonzero(finite)), state.mass[rows][finite], np.ascontiguousarray(velocities[finite]),
        np.ascontiguousarray(spins[finite]), state.inverse_inertia[rows][finite], np.ascontiguousarray(positions[finite]),
        gravity, NO_CLUMP_BODIES)
    return kinetic + rotational + potential

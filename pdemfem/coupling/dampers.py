"""Contact dashpots on a deformable surface: applied by the solid at its own rate, balanced on the particle.

Why.  A contact's force is computed once per DEM step.  Held constant over the solid's
FE sub-steps, its elastic part is harmless, but its dashpot part -C (u_p - s) feeds the
surface velocity s of the *last* interval back to the surface nodes as a force over the
*next* one.  For the surface's high modes (omega h > pi/2, h the interval) that delayed
damping is negative damping: a heavy particle resting on a finely meshed, stiff solid
pumps energy into the solid until it rings and lifts the particle.  Removing the surface
velocity from the contact's relative velocity stops the growth (measured: largest nodal
speed 3e-3 m/s flat over 1 s instead of growing to 0.44 m/s), which locates the cause.

What.  Per contact record the dashpot tensor C = c_n n n^T + c_t (I - n n^T) (c_n = 0 when
the normal force was clamped; sliding, c_t is the dashpot's share of the Coulomb-capped force: the cap's
factor times c_t, pdemfem.contact.tangential_mindlin), the particle's contact-point
velocity u_p and the surface velocity s_prev the DEM step used.  The solid receives

* the contact force without its dashpot part, held over the interval as before, and
* per surface node k of the contact's triangle (barycentric weight w_k >= 0) a dashpot
  w_k C (u_p - v_k) on the node's *own current* velocity, integrated implicitly at every
  FE sub-step (backward Euler: dissipative for any step; kernels.apply_contact_dampers).

Momentum.  Over an interval h the dashpots give the solid the impulse
dt C (u_p - v̄_cur) per contact record (v̄_cur = the contact point's mean velocity over the
interval, sum_k w_k Δx_k / h; dt = the DEM step of the record), the particle got
dt C (u_p - s_prev) in its step; after the advance the particle receives the difference
dt C (v̄_cur - s_prev) (and its moment about the centre), so particles + solid conserve
linear and angular momentum to round-off, as without the dashpots.

Energy.  The dissipated energy the contact kernel booked with s_prev is corrected to the
work the dashpots actually did: on the particle dt F_d · u_p with F_d = -C (u_p - v̄_cur),
on the solid the dashpot impulse times the step's midpoint displacement per damped node
(kernels.apply_contact_dampers, summed in Solid.damper_work_local).

Contact springs over the sub-steps.  The elastic force held over the solid's FE sub-steps is the
force of the surface at the start of the advance: to the surface nodes it is a contact spring
that answers their own motion one advance late, on average (s - 1)/(2 s) of it for s sub-steps.
Like the delayed dashpot, that lag feeds energy into the surface's modes: a sphere resting
without damping on a soft, coarsely meshed block (2 sub-steps) made the energy grow e-fold every
~0.4 s, and every finer or stiffer case drifted upward more slowly.  A linear model (particle,
contact spring, node on an FE spring) shows it for every sub-step count > 1, at a rate growing
with S_n h^2 / m.  So the record carries the contact's stiffness S = S_n n n^T + S_t (I - n n^T) (S_t while it
sticks), and each node k of
its triangle gets the spring w_k S on its own displacement since the start of the
advance, at every sub-step (Solid: the contact springs; nothing changes with one sub-step, where
that displacement is zero).  The model is then stable to round-off for contacts resolved by the
DEM step (omega dt <= 0.2) at any sub-step count and mass ratio.  The particle receives the
opposite impulse after the advance: S sum_k w_k A_k at the contact point (times the record's share of the
window), A_k = the time integral of node k's displacement since the start of the advance over
its sub-steps, gathered with the surface: momentum stays exact.  A solid with `motion` keeps the
held force alone (its nodes' displacements are in the moving frame).  A window of several DEM steps
(fem_every > 1: each record acts by its share of the window) takes the springs while the window is
within half the held force's own limit S_n h^2 / (4 m) <= 1 (WINDOW_SPRING_SHARE,
pdemfem.coupling.check): an impact on a sub-stepped plate at fem_every 2 then lost 8.4e-3 of its
energy instead of gaining 2.0e-2, second order in dt instead of first; at the limit itself (a
resting sphere, 57-step windows) the springs gained 0.74 J of 2182 J where the held force alone
kept the energy.

The blended gap (coupling.transfer: blended) spreads a contact's held normal force over the vertices of
every facet under the particle, so its normal spring goes there too: share rows, one per blended facet
vertex v with its share b_v (omega_t / sum omega times the facet's nearest-point weight: >= 0, summing
to 1), give the node the spring S_n b_v n n^T and the particle, after the advance, the opposite impulse
S_n n sum_v b_v (n . A_v), along n through its centre as the blended normal force acts.  The record
keeps the tangential spring at the nearest point (its S_n is 0).  With one facet under the particle
the shares are the nearest triangle's weights.
"""
from __future__ import annotations

import numpy as np
from numba import njit

from pdemfem.walls.triangle_contact import DAMPING_RECORD_COLUMNS

# A record: particle index, particle id, triangle, weights (3), then the kernel's dashpot record
# (c_n, c_t, normal (3), lever, particle contact-point velocity (3), surface velocity (3), S_n, S_t).
RECORD_INDEX, RECORD_ID, RECORD_TRIANGLE, RECORD_WEIGHTS = 0, 1, 2, 3
RECORD_DAMPING = 6
RECORD_COLUMNS = RECORD_DAMPING + DAMPING_RECORD_COLUMNS
STIFFNESS_COLUMN = 12  # of the kernel's record: S_n, then S_t (0 when sliding)
RECORD_STIFFNESS = RECORD_DAMPING + STIFFNESS_COLUMN


def make_records(particles, ids, triangles, weights, damping) -> np.ndarray:
    """Pack one step's contacts (those with a dashpot or a stiffness) into (n, RECORD_COLUMNS) float rows."""
    active = np.any(damping[:, [0, 1, STIFFNESS_COLUMN, STIFFNESS_COLUMN + 1]] != 0.0, axis=1)
    if not np.any(active):
        return np.zeros((0, RECORD_COLUMNS))
    rows = np.empty((int(active.sum()), RECORD_COLUMNS))
    rows[:, RECORD_INDEX] = particles[active]
    rows[:, RECORD_ID] = ids[active]
    rows[:, RECORD_TRIANGLE] = triangles[active]
    rows[:, RECORD_WEIGHTS:RECORD_WEIGHTS + 3] = weights[active]
    rows[:, RECORD_DAMPING:] = damping[active]
    return rows


# A share row: particle index, particle id (as a record's first two columns), vertex, S_n b_v, normal (3).
SHARE_VERTEX, SHARE_STIFFNESS, SHARE_NORMAL = 2, 3, 4
SHARE_COLUMNS = 7


def make_share_rows(particles, ids, share_contact, share_vertex, share_value, damping) -> np.ndarray:
    """One step's blended contacts' normal springs as (n, SHARE_COLUMNS) rows (module docstring)."""
    active = share_value > 0.0
    rows = np.empty((int(active.sum()), SHARE_COLUMNS))
    contact = share_contact[active]
    rows[:, RECORD_INDEX] = particles[contact]
    rows[:, RECORD_ID] = ids[contact]
    rows[:, SHARE_VERTEX] = share_vertex[active]
    rows[:, SHARE_STIFFNESS] = share_value[active]
    rows[:, SHARE_NORMAL:SHARE_NORMAL + 3] = damping[contact, 2:5]
    return rows


@njit(cache=True)
def node_share_springs(rows, scale, springs):
    """springs[v] += scale S_n b_v n n^T (xx, yy, zz, yz, xz, xy) per share row."""
    for r in range(rows.shape[0]):
        vertex = int(rows[r, SHARE_VERTEX])
        stiffness = scale * rows[r, SHARE_STIFFNESS]
        nx = rows[r, SHARE_NORMAL]
        ny = rows[r, SHARE_NORMAL + 1]
        nz = rows[r, SHARE_NORMAL + 2]
        springs[vertex, 0] += stiffness * nx * nx
        springs[vertex, 1] += stiffness * ny * ny
        springs[vertex, 2] += stiffness * nz * nz
        springs[vertex, 3] += stiffness * ny * nz
        springs[vertex, 4] += stiffness * nx * nz
        springs[vertex, 5] += stiffness * nx * ny


@njit(cache=True)
def balance_share_springs(rows, local_index, spring_integrals, scale, velocities, mass):
    """Each share row's particle (local_index[r] >= 0) takes scale S_n b_v n (n . A_v), A_v the time integral of
    vertex v's displacement over the advance: the opposite of the impulse its spring gave the node."""
    for r in range(rows.shape[0]):
        i = local_index[r]
        if i < 0:
            continue
        vertex = int(rows[r, SHARE_VERTEX])
        nx = rows[r, SHARE_NORMAL]
        ny = rows[r, SHARE_NORMAL + 1]
        nz = rows[r, SHARE_NORMAL + 2]
        along = scale * rows[r, SHARE_STIFFNESS] * (nx * spring_integrals[vertex, 0] + ny * spring_integrals[vertex, 1]
                                                    + nz * spring_integrals[vertex, 2]) / mass[i]
        velocities[i, 0] += along * nx
        velocities[i, 1] += along * ny
        velocities[i, 2] += along * nz


@njit(inline="always", cache=True)
def _dashpot_times(record, x, y, z):
    """C (x, y, z) for the record's dashpot C = c_n n n^T + c_t (I - n n^T)."""
    normal_coefficient = record[RECORD_DAMPING]
    tangential_coefficient = record[RECORD_DAMPING + 1]
    nx = record[RECORD_DAMPING + 2]
    ny = record[RECORD_DAMPING + 3]
    nz = record[RECORD_DAMPING + 4]
    along = (normal_coefficient - tangential_coefficient) * (nx * x + ny * y + nz * z)
    return (tangential_coefficient * x + along * nx, tangential_coefficient * y + along * ny,
            tangential_coefficient * z + along * nz)


@njit(cache=True)
def node_dampers(records, triangles, scale, tensors, targets, previous_forces, springs):
    """Spread the records' dashpots onto the triangles' vertices (scaled by `scale`).

    tensors[v] += scale w C (xx, yy, zz, yz, xz, xy), targets[v] += scale w C u_p and
    previous_forces[v] += scale w C (u_p - s_prev): the dashpot part of the counter-force the
    DEM step already spread, which the solid now gets from the nodal dashpots instead.
    springs[v] += scale w (S_n n n^T + S_t (I - n n^T)) (xx, yy, zz, yz, xz, xy), the contact springs over the
    sub-steps (module docstring); springs with no rows: none."""
    with_springs = springs.shape[0] > 0
    for r in range(records.shape[0]):
        record = records[r]
        t = int(record[RECORD_TRIANGLE])
        if with_springs:
            tangential = scale * record[RECORD_STIFFNESS + 1]
            along = scale * record[RECORD_STIFFNESS] - tangential
            sx = record[RECORD_DAMPING + 2]
            sy = record[RECORD_DAMPING + 3]
            sz = record[RECORD_DAMPING + 4]
            for k in range(3):
                vertex = triangles[t, k]
                w = record[RECORD_WEIGHTS + k]
                springs[vertex, 0] += w * (tangential + along * sx * sx)
                springs[vertex, 1] += w * (tangential + along * sy * sy)
                springs[vertex, 2] += w * (tangential + along * sz * sz)
                springs[vertex, 3] += w * along * sy * sz
                springs[vertex, 4] += w * along * sx * sz
                springs[vertex, 5] += w * along * sx * sy
        cn = record[RECORD_DAMPING]
        ct = record[RECORD_DAMPING + 1]
        nx = record[RECORD_DAMPING + 2]
        ny = record[RECORD_DAMPING + 3]
        nz = record[RECORD_DAMPING + 4]
        ux = record[RECORD_DAMPING + 6]
        uy = record[RECORD_DAMPING + 7]
        uz = record[RECORD_DAMPING + 8]
        gx, gy, gz = _dashpot_times(record, ux, uy, uz)
        px, py, pz = _dashpot_times(record, ux - record[RECORD_DAMPING + 9], uy - record[RECORD_DAMPING + 10],
                                    uz - record[RECORD_DAMPING + 11])
        difference = cn - ct
        for k in range(3):
            vertex = triangles[t, k]
            w = scale * record[RECORD_WEIGHTS + k]
            tensors[vertex, 0] += w * (ct + difference * nx * nx)
            tensors[vertex, 1] += w * (ct + difference * ny * ny)
            tensors[vertex, 2] += w * (ct + difference * nz * nz)
            tensors[vertex, 3] += w * difference * ny * nz
            tensors[vertex, 4] += w * difference * nx * nz
            tensors[vertex, 5] += w * difference * nx * ny
            targets[vertex, 0] += w * gx
            targets[vertex, 1] += w * gy
            targets[vertex, 2] += w * gz
            previous_forces[vertex, 0] += w * px
            previous_forces[vertex, 1] += w * py
            previous_forces[vertex, 2] += w * pz


@njit(inline="always", cache=True)
def _at_contact_point(record, triangle, vertex_values):
    """A per-vertex 3-vector interpolated at the record's contact point (its triangle's weights)."""
    x = 0.0
    y = 0.0
    z = 0.0
    for k in range(3):
        w = record[RECORD_WEIGHTS + k]
        x += w * vertex_values[triangle[k], 0]
        y += w * vertex_values[triangle[k], 1]
        z += w * vertex_values[triangle[k], 2]
    return x, y, z


@njit(inline="always", cache=True)
def _kick_at_contact_point(record, i, jx, jy, jz, velocities, angular_velocities, mass, inverse_inertia):
    """Particle i takes the impulse j at the record's contact point, lever * n below its centre (and its moment)."""
    inverse_mass = 1.0 / mass[i]
    velocities[i, 0] += jx * inverse_mass
    velocities[i, 1] += jy * inverse_mass
    velocities[i, 2] += jz * inverse_mass
    lever = record[RECORD_DAMPING + 5]
    nx = record[RECORD_DAMPING + 2]
    ny = record[RECORD_DAMPING + 3]
    nz = record[RECORD_DAMPING + 4]
    angular_velocities[i, 0] += -lever * (ny * jz - nz * jy) * inverse_inertia[i]
    angular_velocities[i, 1] += -lever * (nz * jx - nx * jz) * inverse_inertia[i]
    angular_velocities[i, 2] += -lever * (nx * jy - ny * jx) * inverse_inertia[i]


@njit(cache=True)
def balance_particles(records, local_index, triangles, vertex_velocities, dt, velocities, angular_velocities, mass,
                      inverse_inertia, spring_integrals, spring_scale):
    """Give each record's particle (local_index[r] >= 0) the impulse dt C (v̄_cur - s_prev) at its contact
    point; vertex_velocities are the mean velocities over the advance just done.  With spring_integrals
    (per vertex, the time integral of its displacement since the start of the advance over its sub-steps;
    no rows: none) also the contact spring's opposite impulse spring_scale S sum_k w_k A_k at the contact point,
    S = S_n n n^T + S_t (I - n n^T).
    Returns the correction of the booked dissipation, sum dt [u_p·C(u_p - v̄_cur) - r·C r], r = u_p - s_prev."""
    dissipation = 0.0
    with_springs = spring_integrals.shape[0] > 0
    for r in range(records.shape[0]):
        i = local_index[r]
        if i < 0:
            continue
        record = records[r]
        t = int(record[RECORD_TRIANGLE])
        if with_springs and (record[RECORD_STIFFNESS] != 0.0 or record[RECORD_STIFFNESS + 1] != 0.0):
            nx = record[RECORD_DAMPING + 2]
            ny = record[RECORD_DAMPING + 3]
            nz = record[RECORD_DAMPING + 4]
            ax, ay, az = _at_contact_point(record, triangles[t], spring_integrals)
            tangential = spring_scale * record[RECORD_STIFFNESS + 1]
            along = (spring_scale * record[RECORD_STIFFNESS] - tangential) * (nx * ax + ny * ay + nz * az)
            jx = tangential * ax + along * nx
            jy = tangential * ay + along * ny
            jz = tangential * az + along * nz
            _kick_at_contact_point(record, i, jx, jy, jz, velocities, angular_velocities, mass, inverse_inertia)
        cx, cy, cz = _at_contact_point(record, triangles[t], vertex_velocities)
        ux = record[RECORD_DAMPING + 6]
        uy = record[RECORD_DAMPING + 7]
        uz = record[RECORD_DAMPING + 8]
        sx = record[RECORD_DAMPING + 9]
        sy = record[RECORD_DAMPING + 10]
        sz = record[RECORD_DAMPING + 11]
        jx, jy, jz = _dashpot_times(record, cx - sx, cy - sy, cz - sz)
        _kick_at_contact_point(record, i, dt * jx, dt * jy, dt * jz, velocities, angular_velocities, mass,
                               inverse_inertia)
        fx, fy, fz = _dashpot_times(record, ux - cx, uy - cy, uz - cz)
        rx, ry, rz = _dashpot_times(record, ux - sx, uy - sy, uz - sz)
        dissipation += dt * (ux * fx + uy * fy + uz * fz
                             - ((ux - sx) * rx + (uy - sy) * ry + (uz - sz) * rz))
    return dissipation

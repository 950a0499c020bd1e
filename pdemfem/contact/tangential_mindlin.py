"""Tangential model `mindlin`: an incremental tangential spring with a dashpot and Coulomb slip.

The spring xi (history) integrates the tangential relative displacement, is turned into the
current tangent plane keeping its length, and gives F_t = -S_t xi - c_t v_t with S_t from the
normal model (Hertz/JKR: Mindlin's 8 G* a; linear: ratio k_n).  Beyond the Coulomb limit
mu (F_n + offset) the force is capped and the spring alone holds it (S_t xi = -F_t).
(Mindlin & Deresiewicz (1953) in the no-slip-annulus simplification of Tsuji et al., Powder
Technol. 71 (1992); the history rotation as in LAMMPS' granular `mindlin`.)
"""
from __future__ import annotations

import math

from numba import njit

from pdemfem.contact.geometry import turn_into_tangent_plane

NAME = "mindlin"
HISTORY_COLUMNS = 3


@njit(inline="always", cache=True)
def force(nx, ny, nz, vx, vy, vz, normal_speed, stiffness, damping, friction_limit,
          history, row, column, dt):
    """(F_t (3), c_t in effect, spring energy after, work taken from the relative motion minus that energy);
    updates xi.  The caller books the energy the spring had before (pdemfem.contact.response).

    c_t is 0 when the contact slides (the force is then not linear in v)."""
    tx = vx - normal_speed * nx
    ty = vy - normal_speed * ny
    tz = vz - normal_speed * nz
    xi_x = history[row, column]
    xi_y = history[row, column + 1]
    xi_z = history[row, column + 2]
    if xi_x != 0.0 or xi_y != 0.0 or xi_z != 0.0:
        xi_x, xi_y, xi_z = turn_into_tangent_plane(xi_x, xi_y, xi_z, nx, ny, nz)
    # The spring's force at the start of the step (for the work below).
    start_x = -stiffness * xi_x
    start_y = -stiffness * xi_y
    start_z = -stiffness * xi_z
    xi_x += tx * dt
    xi_y += ty * dt
    xi_z += tz * dt
    fx = -stiffness * xi_x - damping * tx
    fy = -stiffness * xi_y - damping * ty
    fz = -stiffness * xi_z - damping * tz
    force_squared = fx * fx + fy * fy + fz * fz
    # Squares compared: the square root is only needed by sliding contacts.
    if force_squared > friction_limit * friction_limit:
        # Coulomb slip: cap the force and let the spring alone hold it.  Folding the dashpot into xi
        # as well, xi = -(F_t + c v_t) / S_t, points xi against the force whenever c |v_t| > mu F_n;
        # with S_t growing (Hertz) the next step's force then pushes along the slip.
        scale = friction_limit / math.sqrt(force_squared)
        damping = 0.0
        fx *= scale
        fy *= scale
        fz *= scale
        if stiffness > 0.0:
            xi_x = -fx / stiffness
            xi_y = -fy / stiffness
            xi_z = -fz / stiffness
    history[row, column] = xi_x
    history[row, column + 1] = xi_y
    history[row, column + 2] = xi_z
    energy = 0.5 * stiffness * (xi_x * xi_x + xi_y * xi_y + xi_z * xi_z)
    # Work taken from the relative motion minus what the spring holds now.  The spring's force goes from its
    # value at the start of the step to the new one while the contact point moves by v_t dt: the trapezoid of
    # the two (velocity Verlet's own work on a spring).  The end value alone booked S_t |v_t dt|^2 / 2 a step
    # of a sticking spring as dissipated energy (first order in dt: a closed box of 27 grains, e = 1, friction
    # 0.5, gained 3 % of its energy in the books at the automatic step).  The dashpot's part is -c v_t.
    mean_x = 0.5 * (start_x + fx) - 0.5 * damping * tx
    mean_y = 0.5 * (start_y + fy) - 0.5 * damping * ty
    mean_z = 0.5 * (start_z + fz) - 0.5 * damping * tz
    return fx, fy, fz, damping, energy, -(mean_x * tx + mean_y * ty + mean_z * tz) * dt - energy


"""Rolling model `constant_torque`: a constant directional torque against relative rolling.

M_r = -mu_r R* F_n w_r / |w_r| (w_r: the relative angular velocity in the tangent plane), capped
so that it cannot reverse the rolling within one step (|M_r| <= I* |w_r| / dt).  Cheap and
history-free; a body resting on a slope chatters around rest.  (Zhou et al., Physica A 269 (1999);
model A of Ai et al., Powder Technol. 206 (2011).)
"""
from __future__ import annotations

import math

from numba import njit

from pdemfem.contact.layout import ROLLING_FRICTION

NAME = "constant_torque"
CODE = 1
HISTORY_COLUMNS = 3   # the moment applied at the last evaluation, for the books


def parameters(interaction) -> tuple:
    return ()


@njit(inline="always", cache=True)
def torque(coefficients, a, b, nx, ny, nz, wx, wy, wz, normal_force, normal_stiffness, effective_radius, effective_inertia, rolling_inertia, history, row, column, dt):
    """(moment on the first body (3), spring energy (none), work taken from the relative rolling); keeps the
    moment in the history for the next evaluation's books.

    Velocity Verlet turns the bodies over a step under half of the previous evaluation's moment and half of
    the new one: the work is booked as that trapezoid (a moment's power is M . w whatever the contact's
    geometry).  The new moment alone booked O(dt) too little: a sphere's 45 degree impact on a plane
    (e = 0.99, friction 1, mu_r 0.5) lost 0.38 % of its energy from the books, halving with dt."""
    previous_work = history[row, column] * wx + history[row, column + 1] * wy + history[row, column + 2] * wz
    along_normal = wx * nx + wy * ny + wz * nz
    rx = wx - along_normal * nx
    ry = wy - along_normal * ny
    rz = wz - along_normal * nz
    rolling_speed = math.sqrt(rx * rx + ry * ry + rz * rz)
    moment_x = 0.0
    moment_y = 0.0
    moment_z = 0.0
    if rolling_speed > 0.0 and normal_force > 0.0:
        moment = coefficients[a, b, ROLLING_FRICTION] * effective_radius * normal_force
        moment_limit = effective_inertia * rolling_speed / dt
        if moment > moment_limit:
            moment = moment_limit
        scale = -moment / rolling_speed
        moment_x = scale * rx
        moment_y = scale * ry
        moment_z = scale * rz
    history[row, column] = moment_x
    history[row, column + 1] = moment_y
    history[row, column + 2] = moment_z
    work = -0.5 * dt * (previous_work + moment_x * rx + moment_y * ry + moment_z * rz)
    return moment_x, moment_y, moment_z, 0.0, work


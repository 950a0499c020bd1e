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
HISTORY_COLUMNS = 0


def parameters(interaction) -> tuple:
    return ()


@njit(inline="always", cache=True)
def torque(coefficients, a, b, nx, ny, nz, wx, wy, wz, normal_force, normal_stiffness, effective_radius, effective_inertia, history, row, column, dt):
    """(moment on the first body (3), spring energy (none), work taken from the relative rolling)."""
    along_normal = wx * nx + wy * ny + wz * nz
    rx = wx - along_normal * nx
    ry = wy - along_normal * ny
    rz = wz - along_normal * nz
    rolling_speed = math.sqrt(rx * rx + ry * ry + rz * rz)
    if rolling_speed == 0.0 or normal_force <= 0.0:
        return 0.0, 0.0, 0.0, 0.0, 0.0
    moment = coefficients[a, b, ROLLING_FRICTION] * effective_radius * normal_force
    moment_limit = effective_inertia * rolling_speed / dt
    if moment > moment_limit:
        moment = moment_limit
    scale = -moment / rolling_speed
    return scale * rx, scale * ry, scale * rz, 0.0, moment * rolling_speed * dt


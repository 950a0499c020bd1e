"""Rolling model `elastic_plastic`: a rolling spring-dashpot capped at the rolling limit (EPSD).

Model C of Ai, Chen, Rotter & Ooi, Powder Technol. 206 (2011) 269-282 (the "EPSD" rolling
resistance of LIGGGHTS): an incremental spring moment on the relative rolling rotation,

    M_k += -k_r w_r dt,   k_r = 2.25 mu_r^2 R*^2 S_n,   |M_k| <= mu_r R* F_n  (full mobilisation),

plus a viscous moment M_d = -eta_r 2 sqrt(I_r k_r) w_r while the spring is below the limit
(eta_r: `rolling_damping`, 0.3 by default as Ai et al. recommend; no damping at the limit), with I_r the
bodies' inertias about the contact point, I + m r^2 each, in series (Ai et al. eq. 27): eta_r is then the
fraction of critical damping of a body rocking on its contact (the body's own I gave sqrt(2/7) of it).
Unlike the constant torque, a body on a slope flatter than mu_r comes to a true rest.
The spring moment (on the first body) is the contact's rolling history: it turns with the
tangent plane and is kept while the contact lasts.  Its energy |M_k|^2 / (2 k_r) is booked as
elastic; the rest of the moments' work as dissipated.  The history also keeps the moment applied
at the last evaluation (spring, dashpot and cap): velocity Verlet turns the bodies over a step
under half of it and half of the new one, and the work is booked so.
"""
from __future__ import annotations

import math

from numba import njit

from pdemfem.contact.geometry import turn_into_tangent_plane
from pdemfem.contact.layout import ROLLING_FRICTION, ROLLING_PARAMETERS

NAME = "elastic_plastic"
CODE = 2
HISTORY_COLUMNS = 6   # the moment applied at the last evaluation (3), then the spring moment (3)

STIFFNESS_FACTOR = 2.25              # k_r = 2.25 mu_r^2 R*^2 S_n (Iwashita & Oda; Ai et al. eq. 26)
DAMPING_RATIO = ROLLING_PARAMETERS   # eta_r


def parameters(interaction) -> tuple:
    return (interaction.rolling_damping,)


@njit(inline="always", cache=True)
def torque(coefficients, a, b, nx, ny, nz, wx, wy, wz, normal_force, normal_stiffness, effective_radius, effective_inertia, rolling_inertia, history, row, column, dt):
    mu_r = coefficients[a, b, ROLLING_FRICTION]
    lever_squared = (mu_r * effective_radius) ** 2
    stiffness = STIFFNESS_FACTOR * lever_squared * normal_stiffness
    mx = history[row, column + 3]
    my = history[row, column + 4]
    mz = history[row, column + 5]
    if mx != 0.0 or my != 0.0 or mz != 0.0:
        mx, my, mz = turn_into_tangent_plane(mx, my, mz, nx, ny, nz)
    along_normal = wx * nx + wy * ny + wz * nz
    rx = wx - along_normal * nx
    ry = wy - along_normal * ny
    rz = wz - along_normal * nz
    mx -= stiffness * rx * dt
    my -= stiffness * ry * dt
    mz -= stiffness * rz * dt
    limit = mu_r * effective_radius * max(normal_force, 0.0)
    spring_squared = mx * mx + my * my + mz * mz
    damping = 0.0
    if spring_squared > limit * limit:
        scale = limit / math.sqrt(spring_squared)
        mx *= scale
        my *= scale
        mz *= scale
    elif stiffness > 0.0:
        damping = coefficients[a, b, DAMPING_RATIO] * 2.0 * math.sqrt(rolling_inertia * stiffness)
    energy = 0.5 * (mx * mx + my * my + mz * mz) / stiffness if stiffness > 0.0 else 0.0
    total_x = mx - damping * rx
    total_y = my - damping * ry
    total_z = mz - damping * rz
    # Work taken from the relative rolling minus what the spring holds now (the caller books the before): the
    # trapezoid of the moment applied at the previous evaluation and the new one, as velocity Verlet turns the
    # bodies under half of each.  A moment's power is M . w whatever the contact's geometry, so the previous
    # moment needs no older normal.  The new moment alone booked O(dt) too much: a sphere's 45 degree impact on
    # a plane (e = 0.99, friction 1, mu_r 0.5) gained 0.55 % of its energy in the books, halving with dt.
    previous_work = history[row, column] * wx + history[row, column + 1] * wy + history[row, column + 2] * wz
    history[row, column] = total_x
    history[row, column + 1] = total_y
    history[row, column + 2] = total_z
    history[row, column + 3] = mx
    history[row, column + 4] = my
    history[row, column + 5] = mz
    work = -0.5 * dt * (previous_work + total_x * rx + total_y * ry + total_z * rz)
    return total_x, total_y, total_z, energy, work - energy


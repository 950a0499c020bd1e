"""Tangential model `mindlin`: an incremental tangential spring with a dashpot and Coulomb slip.

The spring xi (history) integrates the tangential relative displacement, is turned into the
current tangent plane keeping its length, and gives F_t = -S_t xi - c_t v_t with S_t from the
normal model (Hertz/JKR: Mindlin's 8 G* a; linear: ratio k_n).  Beyond the Coulomb limit
mu (F_n + offset) the force is capped and the spring scaled with it (it keeps its share of the force).
(Mindlin & Deresiewicz (1953) in the no-slip-annulus simplification of Tsuji et al., Powder
Technol. 71 (1992); the history rotation as in LAMMPS' granular `mindlin`.)
"""
from __future__ import annotations

import math

from numba import njit

from pdemfem.contact.geometry import turn_into_tangent_plane

NAME = "mindlin"
HISTORY_COLUMNS = 6   # xi (3), and the force applied at the last evaluation (3)


@njit(inline="always", cache=True)
def force(nx, ny, nz, vx, vy, vz, normal_speed, previous_vx, previous_vy, previous_vz, stiffness, damping,
          friction_limit, history, row, column, dt):
    """(F_t (3), c_t in effect, spring energy after, work taken from the relative motion minus that energy);
    updates xi and the force kept for the next step's work.  The caller books the energy the spring had
    before (pdemfem.contact.response).

    v is the contact point's relative velocity of this step at this evaluation's geometry (normal and
    levers), previous_v the same velocity at the previous evaluation's geometry: the one the force applied
    then (history columns 3-5) worked on over the first half of this step.

    c_t in effect: sliding, the dashpot's share of the capped force (the cap's factor times c_t).  A deformable
    surface applies that share to its nodes' own current velocity (pdemfem.coupling.dampers) and holds the
    rest: with the whole capped force held, its dashpot part answered the surface velocity of the previous
    interval and pumped energy into a ringing node (a 0.26 kg steel ball resting with friction on a POM beam's
    surface node: the books' total rose with the booked dissipation until the beam blew up; with the share
    applied to the node, the total stayed within 3e-7 J of 5.7e-5 J dissipated)."""
    tx = vx - normal_speed * nx
    ty = vy - normal_speed * ny
    tz = vz - normal_speed * nz
    xi_x = history[row, column]
    xi_y = history[row, column + 1]
    xi_z = history[row, column + 2]
    if xi_x != 0.0 or xi_y != 0.0 or xi_z != 0.0:
        xi_x, xi_y, xi_z = turn_into_tangent_plane(xi_x, xi_y, xi_z, nx, ny, nz)
    xi_x += tx * dt
    xi_y += ty * dt
    xi_z += tz * dt
    fx = -stiffness * xi_x - damping * tx
    fy = -stiffness * xi_y - damping * ty
    fz = -stiffness * xi_z - damping * tz
    force_squared = fx * fx + fy * fy + fz * fz
    # Squares compared: the square root is only needed by sliding contacts.
    if force_squared > friction_limit * friction_limit:
        # Coulomb slip: cap the force, and scale the spring by the same factor, so that it keeps its share
        # of the capped force.  The rule is continuous at the cap (a force just at the limit leaves xi as it
        # is).  Two other rules are not:
        #  - the spring alone holding the capped force, xi = -F_t / S_t, turned the dashpot's part into
        #    stored spring energy that came back as recoil.  At first touch both forces are the dashpot's, so
        #    past tan(theta) = mu sqrt(S_n / S_t) a wall impact's tangential rebound jumped (linear, e = 0.5,
        #    mu = 0.3: 0.627 at 29.0 degrees, 0.505 at 29.6);
        #  - folding the dashpot into xi, xi = -(F_t + c v_t) / S_t, points xi against the force whenever
        #    c |v_t| > mu F_n, and with S_t growing (Hertz) the next step's force then pushes along the slip.
        # Sliding goes on as before: with xi scaled, the next step's force is again at least the cap while
        # the slip keeps its direction, and once the slip stops the spring holds the whole force.
        scale = friction_limit / math.sqrt(force_squared)
        damping *= scale  # the dashpot's share of the capped force (docstring)
        fx *= scale
        fy *= scale
        fz *= scale
        xi_x *= scale
        xi_y *= scale
        xi_z *= scale
    # Work taken from the relative motion minus what the spring holds now.  Velocity Verlet moves the bodies
    # over the step under half of the force applied at the previous evaluation (as that evaluation's levers
    # and normal turn it into torques) and half of the new one: the trapezoid of the two applied forces
    # (spring, dashpot and Coulomb cap included), each on the contact velocity of its own geometry.  The end
    # value alone booked S_t |v_t dt|^2 / 2 a step of a sticking spring as dissipated energy (a closed box of
    # 27 grains, e = 1, friction 0.5, gained 3 % of its energy in the books); the spring's force at the new
    # stiffness and the dashpot at the new speed, with the new levers, still booked O(dt) too much at each
    # impact (a sphere's 45 degree impact on a plane, e = 0.99, friction 1: +0.64 % of its energy at the
    # automatic step, halving with dt; 250 grains settling: +2.1 %).
    previous_fx = history[row, column + 3]
    previous_fy = history[row, column + 4]
    previous_fz = history[row, column + 5]
    history[row, column] = xi_x
    history[row, column + 1] = xi_y
    history[row, column + 2] = xi_z
    history[row, column + 3] = fx
    history[row, column + 4] = fy
    history[row, column + 5] = fz
    energy = 0.5 * stiffness * (xi_x * xi_x + xi_y * xi_y + xi_z * xi_z)
    work = 0.5 * dt * (-(previous_fx * previous_vx + previous_fy * previous_vy + previous_fz * previous_vz)
                       - (fx * tx + fy * ty + fz * tz))
    return fx, fy, fz, damping, energy, work - energy


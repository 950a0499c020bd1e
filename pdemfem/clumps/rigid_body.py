"""Rigid-body step for clumps: velocity Verlet for the centre of mass, symplectic splitting for rotation.

State of n bodies (flat arrays, world frame unless named "body"):

    positions (n, 3)          centres of mass
    velocities (n, 3)
    orientations (n, 4)       unit quaternions (w, x, y, z), body principal frame -> world
    angular_momenta (n, 3)    L about the centre of mass, world frame
    principal_moments (n, 3)  I_1, I_2, I_3 about the principal axes (body frame)
    inverse_masses (n,)
    forces, torques (n, 3)    about the centre of mass

One step, the kick-drift-kick structure of the sphere integrator (pdemfem.particles.integrate):

    kick_bodies(dt/2)   v += dt/2 (F/m + g),  L += dt/2 T          (old forces and torques)
    drift_bodies(dt)    x += dt v;  free rotation of (q, L) for dt  (below)
    (member positions from the body state, contacts, member loads summed to F and T)
    kick_bodies(dt/2)   with the new F and T

Free rotation: the splitting of Dullweber, Leimkuhler & McLachlan, "Symplectic splitting methods
for rigid body molecular dynamics", J. Chem. Phys. 107, 5840 (1997).  The free-rotor Hamiltonian
H = sum_k pi_k^2 / (2 I_k) (pi = R(q)^T L, the body-frame angular momentum) is split into its
three terms; each term's flow is an exact rotation about one principal axis k by the angle
h pi_k / I_k (pi_k is constant along that flow): the orientation turns, q <- q (x) (cos(a/2),
sin(a/2) e_k), and pi turns by -a about e_k, while L = R pi stays fixed.  The symmetric (Strang)
composition

    R_1(dt/2) R_2(dt/2) R_3(dt) R_2(dt/2) R_1(dt/2)

is second order, symplectic and time-reversible.  Because each sub-flow is exact:

  * the world angular momentum L is not touched by the drift at all: a free body keeps L exactly
    (bit for bit); torques change it only through the kicks;
  * |pi| = |L| to round-off (the quaternion is renormalised after each drift);
  * the kinetic energy is not conserved exactly but oscillates with an O(dt^2) amplitude and no
    drift (backward error analysis of a symplectic map);
  * gyroscopic terms (the pi x omega of Euler's equations) are exact inside each sub-flow, so
    asymmetric bodies (the intermediate-axis flip) are followed with an O(dt^2) phase error.

Measured conservation and errors: docs/shapes.md.
"""
from __future__ import annotations

import math

import numpy as np
from numba import njit

from pdemfem.clumps.quaternion import rotation_entries, rotation_matrix
from pdemfem.particles.integrate import keep_largest


@njit(cache=True)
def kick_bodies(count, velocities, angular_momenta, forces, torques, inverse_masses, gravity, half_dt):
    """v += dt/2 (F/m + g);  L += dt/2 T  (world frame; torques about the centres of mass)."""
    for i in range(count):
        for axis in range(3):
            velocities[i, axis] += half_dt * (forces[i, axis] * inverse_masses[i] + gravity[axis])
            angular_momenta[i, axis] += half_dt * torques[i, axis]


# Below this |half angle| the Taylor polynomials of _half_angle_cosine_sine are the cosine and sine to
# round-off: the first omitted terms, a^9/9! and a^8/8!, are below 2.5e-22 and 1e-19 there, under a
# thousandth of an ulp of sin a (>= a/2) and of cos a (~1).  A sub-rotation's angle is then at most
# 1/32 rad, a step's turn of a grain at most 1/16 rad; DEM grains turn far less (omega dt ~ 1e-3),
# larger angles take math.cos and math.sin.
SMALL_HALF_ANGLE = 1.0 / 64.0


@njit(inline="always", cache=True)
def _half_angle_cosine_sine(half_angle, polynomial):
    """(cos a, sin a) of a = half_angle: with `polynomial` (|a| <= SMALL_HALF_ANGLE) the Horner
    polynomials (no library call: ten sine and cosine calls per body per step were a third of the
    drift's cost), else math.cos and math.sin."""
    if polynomial:
        a2 = half_angle * half_angle
        sine = half_angle + half_angle * a2 * (-1.0 / 6.0 + a2 * (1.0 / 120.0 + a2 * (-1.0 / 5040.0)))
        cosine = 1.0 + a2 * (-0.5 + a2 * (1.0 / 24.0 + a2 * (-1.0 / 720.0)))
        return cosine, sine
    return math.cos(half_angle), math.sin(half_angle)


@njit(inline="always", cache=True)
def _principal_rotation(w, x, y, z, p0, p1, p2, axis, factor, polynomial):
    """Exact flow of pi_k^2/(2 I_k) for a time h: q and pi = (p0, p1, p2) turned about body axis
    k = `axis` (a constant where inlined, so the branches fold away) by the angle h pi_k / I_k =
    2 factor pi_k (factor = h / (2 I_k)); returns the turned values."""
    if axis == 0:
        momentum = p0
    elif axis == 1:
        momentum = p1
    else:
        momentum = p2
    c, s = _half_angle_cosine_sine(factor * momentum, polynomial)
    # The full angle's cosine and sine from the half angle's (double-angle identities); 1 - 2 s^2 keeps
    # cos accurate for small angles.
    cos_angle = 1.0 - 2.0 * s * s
    sin_angle = 2.0 * s * c
    # q <- q (x) (c, s e_k): (a1, v1)(a2, v2) = (a1 a2 - v1.v2, a1 v2 + a2 v1 + v1 x v2).
    # Body frame: d pi/dt = pi x omega with omega = (pi_k / I_k) e_k turns (pi_i, pi_j) by -angle,
    # i = k + 1, j = k + 2 (mod 3).
    if axis == 0:
        return (w * c - x * s, x * c + w * s, y * c + z * s, z * c - y * s,
                p0, cos_angle * p1 + sin_angle * p2, -sin_angle * p1 + cos_angle * p2)
    if axis == 1:
        return (w * c - y * s, x * c - z * s, y * c + w * s, z * c + x * s,
                -sin_angle * p2 + cos_angle * p0, p1, cos_angle * p2 + sin_angle * p0)
    return (w * c - z * s, x * c + y * s, y * c - x * s, z * c + w * s,
            cos_angle * p0 + sin_angle * p1, -sin_angle * p0 + cos_angle * p1, p2)


@njit(inline="always", cache=True)
def _splitting(w, x, y, z, p0, p1, p2, factor0, factor1, factor2, polynomial):
    """R_1(dt/2) R_2(dt/2) R_3(dt) R_2(dt/2) R_1(dt/2) of q and pi (factor_k: the half angle per unit
    pi_k of the sub-rotation about k: dt/(4 I_k) for k = 1, 2, dt/(2 I_3)); returns q renormalised."""
    w, x, y, z, p0, p1, p2 = _principal_rotation(w, x, y, z, p0, p1, p2, 0, factor0, polynomial)
    w, x, y, z, p0, p1, p2 = _principal_rotation(w, x, y, z, p0, p1, p2, 1, factor1, polynomial)
    w, x, y, z, p0, p1, p2 = _principal_rotation(w, x, y, z, p0, p1, p2, 2, factor2, polynomial)
    w, x, y, z, p0, p1, p2 = _principal_rotation(w, x, y, z, p0, p1, p2, 1, factor1, polynomial)
    w, x, y, z, p0, p1, p2 = _principal_rotation(w, x, y, z, p0, p1, p2, 0, factor0, polynomial)
    # Each factor is a unit quaternion; renormalising stops the norm's round-off random walk.
    scale = 1.0 / math.sqrt(w * w + x * x + y * y + z * z)
    return w * scale, x * scale, y * scale, z * scale


@njit(inline="always", cache=True)
def _angle_factors(moment0, moment1, moment2, dt):
    """The half angle per unit pi_k of each sub-rotation of the splitting (dt/(4 I_1), dt/(4 I_2),
    dt/(2 I_3)), and the square of their largest (the bound of the half angles per unit |L|)."""
    quarter = 0.25 * dt
    factor0 = quarter / moment0
    factor1 = quarter / moment1
    factor2 = (0.5 * dt) / moment2
    factor = max(factor0, factor1, factor2)
    return factor0, factor1, factor2, factor * factor


@njit(inline="always", cache=True)
def _free_rotation(w, x, y, z, l0, l1, l2, moment0, moment1, moment2, dt):
    """The orientation q = (w, x, y, z) after the free rotation for dt (the splitting of the module
    docstring), renormalised.  L (world) is left unchanged: the free flow conserves it exactly.

    The five half angles are bounded by factor_k |pi| = factor_k |L|: when that bound is within
    SMALL_HALF_ANGLE (nearly always) the splitting runs with the polynomials, as one branch-free
    stretch of arithmetic (the angle factors' divisions off its chain of dependent operations)."""
    r00, r01, r02, r10, r11, r12, r20, r21, r22 = rotation_entries(w, x, y, z)
    p0 = r00 * l0 + r10 * l1 + r20 * l2  # pi = R(q)^T L
    p1 = r01 * l0 + r11 * l1 + r21 * l2
    p2 = r02 * l0 + r12 * l1 + r22 * l2
    factor0, factor1, factor2, factor_squared = _angle_factors(moment0, moment1, moment2, dt)
    if factor_squared * (l0 * l0 + l1 * l1 + l2 * l2) <= SMALL_HALF_ANGLE * SMALL_HALF_ANGLE:
        return _splitting(w, x, y, z, p0, p1, p2, factor0, factor1, factor2, True)
    # (also a non-finite L: the math functions carry its NaN on)
    return _splitting(w, x, y, z, p0, p1, p2, factor0, factor1, factor2, False)


@njit(inline="always", cache=True)
def _spin(r00, r01, r02, r10, r11, r12, r20, r21, r22, l0, l1, l2, moment0, moment1, moment2):
    """omega (world) = R diag(1/I) R^T L."""
    b0 = (r00 * l0 + r10 * l1 + r20 * l2) / moment0
    b1 = (r01 * l0 + r11 * l1 + r21 * l2) / moment1
    b2 = (r02 * l0 + r12 * l1 + r22 * l2) / moment2
    return (r00 * b0 + r01 * b1 + r02 * b2, r10 * b0 + r11 * b1 + r12 * b2, r20 * b0 + r21 * b1 + r22 * b2)


# The kernels below pass scalars (not array rows) to their inlined helpers: a helper taking arrays
# costs reference-count updates per call, which made the drift and omega several times slower.

@njit(cache=True)
def drift_bodies(count, positions, velocities, orientations, angular_momenta, principal_moments, dt):
    """x += dt v, and the free rotation of each body for dt (the splitting of the module docstring).

    L (world) is left unchanged: the free flow conserves it exactly.
    """
    for i in range(count):
        for axis in range(3):
            positions[i, axis] += dt * velocities[i, axis]
        (orientations[i, 0], orientations[i, 1], orientations[i, 2], orientations[i, 3]) = _free_rotation(
            orientations[i, 0], orientations[i, 1], orientations[i, 2], orientations[i, 3], angular_momenta[i, 0],
            angular_momenta[i, 1], angular_momenta[i, 2], principal_moments[i, 0], principal_moments[i, 1],
            principal_moments[i, 2], dt)


# The bodies' rotation runs over columns (one row per quantity, one column per body) so that the
# compiler turns its loop into vector instructions, several bodies per instruction: the drift is a long
# chain of arithmetic per body (~300 operations) and, one body at a time, it cost ~50 ns per body, half
# the clump step's integration.  The loop works in place on ROTATION_ROWS rows:
#   before  0-3 q (w, x, y, z), 4-6 L (world)
#   after   0-3 q after the free rotation, 4-6 omega (world), 7 1.0 where the body needs the library
#           cosine and sine (its half angles may exceed SMALL_HALF_ANGLE, or L is not finite), else 0.0
#   kept    8-10 the principal moments I_1, I_2, I_3, 11-13 the half angle per unit pi_k of each
#           sub-rotation (dt/(4 I_1), dt/(4 I_2), dt/(2 I_3)), 14 the square of their largest
#           (rotation_constants, once per dt and set of bodies: they do not change from step to step,
#           and three of the loop's seven divisions went with them)
# (In place because the compiler vectorises only a loop whose stores it can prove independent with few
# run-time address checks: a separate output array of more rows was left scalar, and so was this loop
# when it also wrote R(q) into nine more rows.)
ROTATION_ROWS = 15


@njit(cache=True)
def rotation_constants(count, principal_moments, dt, work):
    """Rows 8-14 of `work` (above) for the bodies' moments and the step dt: the moments, the angle
    factors and the square of the largest (_angle_factors, as _free_rotation takes them)."""
    for i in range(count):
        moment0 = principal_moments[i, 0]
        moment1 = principal_moments[i, 1]
        moment2 = principal_moments[i, 2]
        factor0, factor1, factor2, factor_squared = _angle_factors(moment0, moment1, moment2, dt)
        work[8, i] = moment0
        work[9, i] = moment1
        work[10, i] = moment2
        work[11, i] = factor0
        work[12, i] = factor1
        work[13, i] = factor2
        work[14, i] = factor_squared


@njit(cache=True, error_model="numpy")
def free_rotation_columns(count, work):
    """_free_rotation's polynomial branch and omega = R diag(1/I) R^T L of its result, over the columns of
    `work` (rows above; rows 8-14 from rotation_constants), in place; row 7 flags the bodies whose result
    must be recomputed with the library functions (as kick_drift_bodies does).

    The loop has no branch and, with error_model="numpy", no division-by-zero exit, which is what lets
    it be vectorised; every operation is the one of the per-body kernels (no fused multiply-adds, no
    reassociation), so each body's values are those of drift_bodies and _spin bit for bit, however
    many bodies share an instruction (tested)."""
    bound = SMALL_HALF_ANGLE * SMALL_HALF_ANGLE
    for i in range(count):
        w = work[0, i]
        x = work[1, i]
        y = work[2, i]
        z = work[3, i]
        l0 = work[4, i]
        l1 = work[5, i]
        l2 = work[6, i]
        moment0 = work[8, i]
        moment1 = work[9, i]
        moment2 = work[10, i]
        factor0 = work[11, i]
        factor1 = work[12, i]
        factor2 = work[13, i]
        r00, r01, r02, r10, r11, r12, r20, r21, r22 = rotation_entries(w, x, y, z)
        p0 = r00 * l0 + r10 * l1 + r20 * l2  # pi = R(q)^T L
        p1 = r01 * l0 + r11 * l1 + r21 * l2
        p2 = r02 * l0 + r12 * l1 + r22 * l2
        small = work[14, i] * (l0 * l0 + l1 * l1 + l2 * l2) <= bound
        w, x, y, z = _splitting(w, x, y, z, p0, p1, p2, factor0, factor1, factor2, True)
        r00, r01, r02, r10, r11, r12, r20, r21, r22 = rotation_entries(w, x, y, z)
        omega0, omega1, omega2 = _spin(r00, r01, r02, r10, r11, r12, r20, r21, r22, l0, l1, l2, moment0, moment1,
                                       moment2)
        work[0, i] = w
        work[1, i] = x
        work[2, i] = y
        work[3, i] = z
        work[4, i] = omega0
        work[5, i] = omega1
        work[6, i] = omega2
        work[7, i] = 0.0 if small else 1.0


@njit(cache=True)
def kick_drift_bodies(count, positions, velocities, orientations, angular_momenta, forces, torques, inverse_masses,
                      principal_moments, gravity, half_dt, dt, rotations, angular_velocities, work):
    """The step's first half over the bodies alone (first_half_bodies without members; `work` is filled
    by rotation_constants here)."""
    rotation_constants(count, principal_moments, dt, work)
    no_rows = np.zeros(0, dtype=np.int64)
    first_half_bodies(count, positions, velocities, orientations, angular_momenta, forces, torques, inverse_masses,
                      principal_moments, gravity, 0.0, half_dt, dt, rotations, angular_velocities, work, 0, no_rows,
                      np.zeros((0, 3)), np.zeros((0, 3)), np.zeros((0, 3)), np.zeros((0, 3)), np.zeros((0, 3)),
                      np.zeros((0, 3)), np.zeros((0, 3)), np.zeros((0, 3)))


@njit(cache=True)
def first_half_bodies(count, positions, velocities, orientations, angular_momenta, forces, torques, inverse_masses,
                      principal_moments, gravity, pending_half_dt, half_dt, dt, rotations, angular_velocities, work,
                      row_count, row_body, row_offsets, levers, row_positions, row_velocities, row_angular_velocities,
                      positions_at_build, row_forces, row_torques):
    """The step's first half over the bodies and their members: kick_bodies(dt/2) and drift_bodies(dt)
    (the same arithmetic, the same values), rotations[i] = R(q) of the new orientation, omega from L,
    and place_members for the member rows among rows 0 .. row_count - 1 (row_body[row]: the local index
    of the row's body, -1 for a free sphere; row_offsets[row]: its offset; levers[row] receives its
    lever), whose loads in row_forces and row_torques (summed onto the bodies last step) it zeroes for
    the next evaluation.  `work`: (ROTATION_ROWS, >= count), rows 8-14 set by rotation_constants for
    these bodies and this dt.  Returns the largest squared displacement of a member since the list build
    (inf when one is not finite).

    pending_half_dt: the last step's load sum and second half kick, when they were left for this kernel
    (ClumpBodies.sum_loads, second_half), the kick's dt/2.  The kernel then sums the member rows' loads onto
    the bodies first (sum_body_loads, which is why the rows' loads are zeroed here and not before), and its
    kick runs kick_bodies(pending_half_dt) and kick_bodies(half_dt) in turn on those forces and torques,
    each value rounded as by the kernels in turn.  0.0: the bodies hold the summed loads and the kicked
    state (no step has a half step of 0).

    The kick and the translation go body by body, then q and L are gathered into the columns of `work`;
    the rotation and omega go over the columns (free_rotation_columns, vectorised); a pass body by body
    writes them back, the rare body beyond the polynomials' range recomputed with math.cos and math.sin
    (_free_rotation).  Then the members are placed in row order, each reading its body's new state: the
    rows' arrays are walked in order (a body's members are scattered over the rows), which made the
    placement ~25 % cheaper than body by body with its members (4000 members: 29 against 39 us)."""
    # Flat views, components written out: the compiler then knows each row's length (2000 bodies: the kick
    # pass 9 against 12 us with two-index rows, the whole kernel 56 against 59 us; the same arithmetic).
    position, velocity, orientation = positions.reshape(-1), velocities.reshape(-1), orientations.reshape(-1)
    momentum, force, torque = angular_momenta.reshape(-1), forces.reshape(-1), torques.reshape(-1)
    moment, rotation, spin = principal_moments.reshape(-1), rotations.reshape(-1), angular_velocities.reshape(-1)
    gravity_x, gravity_y, gravity_z = gravity[0], gravity[1], gravity[2]
    pending = pending_half_dt != 0.0
    if pending:  # the last step's load sum (its arguments are this kernel's own: no call of its own)
        sum_body_loads(count, row_count, row_body, levers, row_forces, row_torques, forces, torques)
    work_w, work_x, work_y, work_z = work[0], work[1], work[2], work[3]
    work_l0, work_l1, work_l2 = work[4], work[5], work[6]
    # The kick and the translation apart from the gathering into columns: two simple loops instead of one
    # (2000 bodies: 7.2 against 11.3 us; kick_bodies' arithmetic).  The pending second half kick adds the
    # same accelerations once more before (one pass over the bodies instead of a kernel of its own).
    for i in range(count):
        k = 3 * i
        inverse_mass = inverse_masses[i]
        a0 = force[k] * inverse_mass + gravity_x
        a1 = force[k + 1] * inverse_mass + gravity_y
        a2 = force[k + 2] * inverse_mass + gravity_z
        v0, v1, v2 = velocity[k], velocity[k + 1], velocity[k + 2]
        t0, t1, t2 = torque[k], torque[k + 1], torque[k + 2]
        l0, l1, l2 = momentum[k], momentum[k + 1], momentum[k + 2]
        if pending:
            v0 += pending_half_dt * a0
            v1 += pending_half_dt * a1
            v2 += pending_half_dt * a2
            l0 += pending_half_dt * t0
            l1 += pending_half_dt * t1
            l2 += pending_half_dt * t2
        v0 += half_dt * a0
        v1 += half_dt * a1
        v2 += half_dt * a2
        velocity[k] = v0
        velocity[k + 1] = v1
        velocity[k + 2] = v2
        momentum[k] = l0 + half_dt * t0
        momentum[k + 1] = l1 + half_dt * t1
        momentum[k + 2] = l2 + half_dt * t2
        position[k] += dt * v0
        position[k + 1] += dt * v1
        position[k + 2] += dt * v2
    for i in range(count):
        k = 3 * i
        work_l0[i] = momentum[k]
        work_l1[i] = momentum[k + 1]
        work_l2[i] = momentum[k + 2]
        q = 4 * i
        work_w[i] = orientation[q]
        work_x[i] = orientation[q + 1]
        work_y[i] = orientation[q + 2]
        work_z[i] = orientation[q + 3]
    free_rotation_columns(count, work)
    needs_library_functions = work[7]  # row 7 now flags the bodies beyond the polynomials' range
    for i in range(count):
        k = 3 * i
        q = 4 * i
        if needs_library_functions[i] == 0.0:
            w, x, y, z = work_w[i], work_x[i], work_y[i], work_z[i]
            r00, r01, r02, r10, r11, r12, r20, r21, r22 = rotation_entries(w, x, y, z)
            omega0, omega1, omega2 = work_l0[i], work_l1[i], work_l2[i]
        else:  # orientations still holds the old q
            w, x, y, z = _free_rotation(orientation[q], orientation[q + 1], orientation[q + 2], orientation[q + 3],
                                        momentum[k], momentum[k + 1], momentum[k + 2], moment[k], moment[k + 1],
                                        moment[k + 2], dt)
            r00, r01, r02, r10, r11, r12, r20, r21, r22 = rotation_entries(w, x, y, z)
            omega0, omega1, omega2 = _spin(r00, r01, r02, r10, r11, r12, r20, r21, r22, momentum[k],
                                           momentum[k + 1], momentum[k + 2], moment[k], moment[k + 1], moment[k + 2])
        orientation[q] = w
        orientation[q + 1] = x
        orientation[q + 2] = y
        orientation[q + 3] = z
        e = 9 * i
        rotation[e] = r00
        rotation[e + 1] = r01
        rotation[e + 2] = r02
        rotation[e + 3] = r10
        rotation[e + 4] = r11
        rotation[e + 5] = r12
        rotation[e + 6] = r20
        rotation[e + 7] = r21
        rotation[e + 8] = r22
        spin[k] = omega0
        spin[k + 1] = omega1
        spin[k + 2] = omega2
    offset, lever = row_offsets.reshape(-1), levers.reshape(-1)
    row_position, row_velocity = row_positions.reshape(-1), row_velocities.reshape(-1)
    row_spin, position_at_build = row_angular_velocities.reshape(-1), positions_at_build.reshape(-1)
    row_force, row_torque = row_forces.reshape(-1), row_torques.reshape(-1)
    # The largest displacement as a plain maximum with the non-finite test apart (kick_drift's form): the
    # same result as keep_largest's, without its branches.
    largest = 0.0
    finite = True
    for i in range(row_count):
        b = row_body[i]
        if b < 0:
            continue
        row = 3 * i
        k = 3 * b
        e = 9 * b
        o0, o1, o2 = offset[row], offset[row + 1], offset[row + 2]
        # the lever R(q) offset, as member_levers computes it
        lever0 = rotation[e] * o0 + rotation[e + 1] * o1 + rotation[e + 2] * o2
        lever1 = rotation[e + 3] * o0 + rotation[e + 4] * o1 + rotation[e + 5] * o2
        lever2 = rotation[e + 6] * o0 + rotation[e + 7] * o1 + rotation[e + 8] * o2
        lever[row] = lever0
        lever[row + 1] = lever1
        lever[row + 2] = lever2
        p0 = position[k] + lever0
        p1 = position[k + 1] + lever1
        p2 = position[k + 2] + lever2
        row_position[row] = p0
        row_position[row + 1] = p1
        row_position[row + 2] = p2
        offset0 = p0 - position_at_build[row]
        offset1 = p1 - position_at_build[row + 1]
        offset2 = p2 - position_at_build[row + 2]
        displacement_squared = offset0 * offset0 + offset1 * offset1 + offset2 * offset2
        finite &= displacement_squared < np.inf
        largest = max(largest, displacement_squared)
        omega0, omega1, omega2 = spin[k], spin[k + 1], spin[k + 2]
        row_velocity[row], row_velocity[row + 1], row_velocity[row + 2] = _member_velocity(
            velocity[k], velocity[k + 1], velocity[k + 2], omega0, omega1, omega2, lever0, lever1, lever2)
        row_spin[row] = omega0
        row_spin[row + 1] = omega1
        row_spin[row + 2] = omega2
        # the member's loads are used up (summed onto the body): zeroed for the next evaluation
        row_force[row] = 0.0
        row_force[row + 1] = 0.0
        row_force[row + 2] = 0.0
        row_torque[row] = 0.0
        row_torque[row + 1] = 0.0
        row_torque[row + 2] = 0.0
    return largest if finite else np.inf


@njit(cache=True)
def sum_body_loads(count, row_count, row_body, levers, forces, torques, body_forces, body_torques):
    """sum_row_loads over the member rows among rows 0 .. row_count - 1, in row order (row_body, levers as
    in first_half_bodies), so each body's loads are added in the order of its rows, as sum_row_loads adds
    them given the rows ascending: F_b = sum f_m, T_b = sum r_m x f_m + t_m.  The bodies' loads are zeroed
    first.  (Body by body, each body's loads added in registers and written once, the sum took 13.6 us for
    4000 members; in row order, reading the rows' loads in order, 11.9 us.)"""
    lever, force, torque = levers.reshape(-1), forces.reshape(-1), torques.reshape(-1)
    body_force, body_torque = body_forces.reshape(-1), body_torques.reshape(-1)
    for k in range(3 * count):
        body_force[k] = 0.0
        body_torque[k] = 0.0
    for i in range(row_count):
        b = row_body[i]
        if b < 0:
            continue
        row = 3 * i
        k = 3 * b
        r0 = lever[row]
        r1 = lever[row + 1]
        r2 = lever[row + 2]
        f0 = force[row]
        f1 = force[row + 1]
        f2 = force[row + 2]
        body_force[k] += f0
        body_force[k + 1] += f1
        body_force[k + 2] += f2
        body_torque[k] += r1 * f2 - r2 * f1 + torque[row]
        body_torque[k + 1] += r2 * f0 - r0 * f2 + torque[row + 1]
        body_torque[k + 2] += r0 * f1 - r1 * f0 + torque[row + 2]


@njit(cache=True)
def second_half_bodies(count, velocities, angular_momenta, forces, torques, inverse_masses, gravity, half_dt,
                       rotations, principal_moments, angular_velocities, row_count, row_body, levers,
                       row_velocities, row_angular_velocities):
    """kick_bodies_and_spin over the bodies, then move_members over the member rows in row order (row_body,
    levers as in first_half_bodies)."""
    velocity, momentum, force, torque = (velocities.reshape(-1), angular_momenta.reshape(-1), forces.reshape(-1),
                                         torques.reshape(-1))
    rotation, moment, spin = rotations.reshape(-1), principal_moments.reshape(-1), angular_velocities.reshape(-1)
    gravity_x, gravity_y, gravity_z = gravity[0], gravity[1], gravity[2]
    # The kick apart from omega, as in first_half_bodies (2000 bodies: 12.8 against 14.1 us).
    for b in range(count):
        k = 3 * b
        inverse_mass = inverse_masses[b]
        velocity[k] += half_dt * (force[k] * inverse_mass + gravity_x)
        velocity[k + 1] += half_dt * (force[k + 1] * inverse_mass + gravity_y)
        velocity[k + 2] += half_dt * (force[k + 2] * inverse_mass + gravity_z)
        momentum[k] += half_dt * torque[k]
        momentum[k + 1] += half_dt * torque[k + 1]
        momentum[k + 2] += half_dt * torque[k + 2]
    for b in range(count):
        k = 3 * b
        e = 9 * b
        omega0, omega1, omega2 = _spin(rotation[e], rotation[e + 1], rotation[e + 2], rotation[e + 3],
                                       rotation[e + 4], rotation[e + 5], rotation[e + 6], rotation[e + 7],
                                       rotation[e + 8], momentum[k], momentum[k + 1], momentum[k + 2], moment[k],
                                       moment[k + 1], moment[k + 2])
        spin[k] = omega0
        spin[k + 1] = omega1
        spin[k + 2] = omega2
    lever, row_velocity, row_spin = levers.reshape(-1), row_velocities.reshape(-1), row_angular_velocities.reshape(-1)
    for i in range(row_count):
        b = row_body[i]
        if b < 0:
            continue
        row = 3 * i
        k = 3 * b
        omega0, omega1, omega2 = spin[k], spin[k + 1], spin[k + 2]
        row_velocity[row], row_velocity[row + 1], row_velocity[row + 2] = _member_velocity(
            velocity[k], velocity[k + 1], velocity[k + 2], omega0, omega1, omega2, lever[row], lever[row + 1],
            lever[row + 2])
        row_spin[row] = omega0
        row_spin[row + 1] = omega1
        row_spin[row + 2] = omega2


@njit(cache=True)
def index_members(owned_count, body, offsets, body_ids, rotations, row_body, levers):
    """The body of each owned row: row_body[row] = b where body[row] (a global body id) is body_ids[b]
    (ids sorted), -1 for a free sphere (body -1); levers[row] = R(q_b) offsets[row] for the members
    (rotations: body_rotations).  row_body, levers: at least owned_count long.  Returns the member count,
    or -1 - row for the first row whose body is not held here.

    The body of a row is found in a table over the span of the held ids (4 bytes per id, at most the
    scene's body count): a binary search per member, at random places, cost several times more."""
    bodies = body_ids.shape[0]
    lowest = body_ids[0] if bodies else 0
    span = body_ids[bodies - 1] - lowest + 1 if bodies else 0
    table = np.full(span, -1, dtype=np.int32)
    for b in range(bodies):
        table[body_ids[b] - lowest] = b
    members = 0
    for i in range(owned_count):
        row_body[i] = -1
        if body[i] < 0:
            continue
        key = body[i] - lowest
        if key < 0 or key >= span or table[key] < 0:
            return -1 - i
        b = table[key]
        row_body[i] = b
        members += 1
        for axis in range(3):
            levers[i, axis] = (rotations[b, axis, 0] * offsets[i, 0] + rotations[b, axis, 1] * offsets[i, 1]
                               + rotations[b, axis, 2] * offsets[i, 2])
    return members


@njit(cache=True)
def kick_bodies_and_spin(count, velocities, angular_momenta, forces, torques, inverse_masses, gravity, half_dt,
                         rotations, principal_moments, angular_velocities):
    """The step's second half over the bodies: kick_bodies(dt/2), then omega from L (R = rotations, set
    by this step's drift: the orientation has not changed since)."""
    for i in range(count):
        for axis in range(3):
            velocities[i, axis] += half_dt * (forces[i, axis] * inverse_masses[i] + gravity[axis])
            angular_momenta[i, axis] += half_dt * torques[i, axis]
        (angular_velocities[i, 0], angular_velocities[i, 1], angular_velocities[i, 2]) = _spin(
            rotations[i, 0, 0], rotations[i, 0, 1], rotations[i, 0, 2], rotations[i, 1, 0], rotations[i, 1, 1],
            rotations[i, 1, 2], rotations[i, 2, 0], rotations[i, 2, 1], rotations[i, 2, 2], angular_momenta[i, 0],
            angular_momenta[i, 1], angular_momenta[i, 2], principal_moments[i, 0], principal_moments[i, 1],
            principal_moments[i, 2])


@njit(cache=True)
def body_rotations(count, orientations, rotations):
    """rotations[i] = R(q_i) for every body ((n, 3, 3), the matrices the members and the loads read)."""
    for i in range(count):
        (rotations[i, 0, 0], rotations[i, 0, 1], rotations[i, 0, 2], rotations[i, 1, 0], rotations[i, 1, 1],
         rotations[i, 1, 2], rotations[i, 2, 0], rotations[i, 2, 1], rotations[i, 2, 2]) = rotation_entries(
            orientations[i, 0], orientations[i, 1], orientations[i, 2], orientations[i, 3])


@njit(cache=True)
def angular_velocities_from_momenta(count, orientations, angular_momenta, principal_moments, out):
    """out[i] = omega (world) = R diag(1/I) R^T L."""
    for i in range(count):
        r00, r01, r02, r10, r11, r12, r20, r21, r22 = rotation_entries(
            orientations[i, 0], orientations[i, 1], orientations[i, 2], orientations[i, 3])
        (out[i, 0], out[i, 1], out[i, 2]) = _spin(r00, r01, r02, r10, r11, r12, r20, r21, r22, angular_momenta[i, 0],
                                                  angular_momenta[i, 1], angular_momenta[i, 2],
                                                  principal_moments[i, 0], principal_moments[i, 1],
                                                  principal_moments[i, 2])


@njit(cache=True)
def angular_momenta_from_velocities(count, orientations, angular_velocities, principal_moments, out):
    """out[i] = L (world) = R diag(I) R^T omega: the initial condition from a given angular velocity."""
    rotation = np.empty((3, 3))
    body_momentum = np.empty(3)
    for i in range(count):
        rotation_matrix(orientations[i, 0], orientations[i, 1], orientations[i, 2], orientations[i, 3], rotation)
        for row in range(3):
            body_momentum[row] = (rotation[0, row] * angular_velocities[i, 0] + rotation[1, row] * angular_velocities[i, 1]
                                  + rotation[2, row] * angular_velocities[i, 2]) * principal_moments[i, row]
        for row in range(3):
            out[i, row] = (rotation[row, 0] * body_momentum[0] + rotation[row, 1] * body_momentum[1]
                           + rotation[row, 2] * body_momentum[2])


@njit(cache=True)
def rotational_energies(count, orientations, angular_momenta, principal_moments, out):
    """out[i] = sum_k pi_k^2 / (2 I_k), pi = R^T L."""
    rotation = np.empty((3, 3))
    for i in range(count):
        rotation_matrix(orientations[i, 0], orientations[i, 1], orientations[i, 2], orientations[i, 3], rotation)
        energy = 0.0
        for row in range(3):
            pi = (rotation[0, row] * angular_momenta[i, 0] + rotation[1, row] * angular_momenta[i, 1]
                  + rotation[2, row] * angular_momenta[i, 2])
            energy += 0.5 * pi * pi / principal_moments[i, row]
        out[i] = energy


@njit(inline="always", cache=True)
def _member_velocity(body_velocity0, body_velocity1, body_velocity2, w0, w1, w2, r0, r1, r2):
    """v = v_b + omega x r."""
    return (body_velocity0 + w1 * r2 - w2 * r1, body_velocity1 + w2 * r0 - w0 * r2, body_velocity2 + w0 * r1 - w1 * r0)


# The member-by-member kernels below (members in any order, each naming its body) serve member_states
# and sum_member_loads; the step runs their arithmetic in fewer passes (first_half_bodies, sum_body_loads,
# second_half_bodies), tested equal to them bit for bit.

@njit(cache=True)
def member_levers(member_count, member_body, member_offsets, rotations, levers):
    """levers[m] = R(q_b) offset_m, the member's centre relative to its body's centre of mass (world;
    rotations: body_rotations)."""
    for m in range(member_count):
        b = member_body[m]
        for axis in range(3):
            levers[m, axis] = (rotations[b, axis, 0] * member_offsets[m, 0]
                               + rotations[b, axis, 1] * member_offsets[m, 1]
                               + rotations[b, axis, 2] * member_offsets[m, 2])


@njit(inline="always", cache=True)
def _set_member_motion(i, b, m, levers, body_velocities, body_angular_velocities, velocities, angular_velocities):
    """Member row i of body b (lever row m): the body's velocity at the member's centre, and its spin."""
    w0 = body_angular_velocities[b, 0]
    w1 = body_angular_velocities[b, 1]
    w2 = body_angular_velocities[b, 2]
    velocities[i, 0], velocities[i, 1], velocities[i, 2] = _member_velocity(
        body_velocities[b, 0], body_velocities[b, 1], body_velocities[b, 2], w0, w1, w2, levers[m, 0],
        levers[m, 1], levers[m, 2])
    angular_velocities[i, 0] = w0
    angular_velocities[i, 1] = w1
    angular_velocities[i, 2] = w2


@njit(cache=True)
def place_members(rows, member_body, member_offsets, rotations, body_positions, body_velocities,
                  body_angular_velocities, levers, positions, velocities, angular_velocities, positions_at_build):
    """World state of the member spheres from their bodies' state, written into their particle rows
    (member m is row rows[m]).

    member_offsets (m, 3): each member's centre relative to its body's centre of mass, in the body
    principal frame (`shape.MassProperties.member_offsets`).  r = R(q) offset (kept in levers[m] for
    the load sum and the second half);  x = x_b + r;  v = v_b + omega x r;  the member spins with its
    body's omega.  Returns the largest squared displacement of a member since the list build (inf
    when one is not finite)."""
    member_levers(rows.shape[0], member_body, member_offsets, rotations, levers)
    largest = 0.0
    for m in range(rows.shape[0]):
        b = member_body[m]
        i = rows[m]
        displacement_squared = 0.0
        for axis in range(3):
            positions[i, axis] = body_positions[b, axis] + levers[m, axis]
            offset = positions[i, axis] - positions_at_build[i, axis]
            displacement_squared += offset * offset
        largest = keep_largest(largest, displacement_squared)
        _set_member_motion(i, b, m, levers, body_velocities, body_angular_velocities, velocities, angular_velocities)
    return largest


@njit(cache=True)
def move_members(rows, member_body, levers, body_velocities, body_angular_velocities, velocities, angular_velocities):
    """The members' velocities and spins after the second half kick (positions and levers unchanged)."""
    for m in range(rows.shape[0]):
        b = member_body[m]
        i = rows[m]
        _set_member_motion(i, b, m, levers, body_velocities, body_angular_velocities, velocities, angular_velocities)


@njit(cache=True)
def member_states(member_count, member_body, member_offsets, body_positions, body_velocities, orientations,
                  body_angular_velocities, out_positions, out_velocities, out_angular_velocities):
    """place_members into separate arrays (member m in row m), from the orientations."""
    rotations = np.empty((orientations.shape[0], 3, 3))
    body_rotations(orientations.shape[0], orientations, rotations)
    place_members(np.arange(member_count), member_body, member_offsets, rotations, body_positions, body_velocities,
                  body_angular_velocities, np.empty((member_count, 3)), out_positions, out_velocities,
                  out_angular_velocities, np.zeros((member_count, 3)))


@njit(cache=True)
def sum_row_loads(rows, member_body, levers, forces, torques, body_forces, body_torques):
    """Zero the bodies' loads, then add their members' (member m is particle row rows[m]):
    F_b += f_m;  T_b += r_m x f_m + t_m.

    r_m = R(q) offset is the lever from the centre of mass to the member centre (place_members),
    taken from the orientation (not from positions, which may be periodic images).  t_m is the
    member's own torque about its centre (the contact moments r_c x f of its contacts plus rolling
    torques)."""
    body_forces[:] = 0.0
    body_torques[:] = 0.0
    for m in range(rows.shape[0]):
        b = member_body[m]
        i = rows[m]
        r0 = levers[m, 0]
        r1 = levers[m, 1]
        r2 = levers[m, 2]
        f0 = forces[i, 0]
        f1 = forces[i, 1]
        f2 = forces[i, 2]
        body_forces[b, 0] += f0
        body_forces[b, 1] += f1
        body_forces[b, 2] += f2
        body_torques[b, 0] += r1 * f2 - r2 * f1 + torques[i, 0]
        body_torques[b, 1] += r2 * f0 - r0 * f2 + torques[i, 1]
        body_torques[b, 2] += r0 * f1 - r1 * f0 + torques[i, 2]


@njit(cache=True)
def sum_member_loads(member_count, member_body, member_offsets, orientations, member_forces, member_torques,
                     body_forces, body_torques):
    """sum_row_loads from separate arrays (member m in row m), the levers from the orientations; the
    bodies' loads are zeroed first."""
    rotations = np.empty((orientations.shape[0], 3, 3))
    body_rotations(orientations.shape[0], orientations, rotations)
    levers = np.empty((member_count, 3))
    member_levers(member_count, member_body, member_offsets, rotations, levers)
    sum_row_loads(np.arange(member_count), member_body, levers, member_forces, member_torques, body_forces,
                  body_torques)

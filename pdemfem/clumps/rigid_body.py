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

from pdemfem.clumps.quaternion import rotation_matrix
from pdemfem.particles.integrate import keep_largest


@njit(cache=True)
def kick_bodies(count, velocities, angular_momenta, forces, torques, inverse_masses, gravity, half_dt):
    """v += dt/2 (F/m + g);  L += dt/2 T  (world frame; torques about the centres of mass)."""
    for i in range(count):
        for axis in range(3):
            velocities[i, axis] += half_dt * (forces[i, axis] * inverse_masses[i] + gravity[axis])
            angular_momenta[i, axis] += half_dt * torques[i, axis]


@njit(inline="always", cache=True)
def _principal_rotation(w, x, y, z, p0, p1, p2, axis, moment, h):
    """Exact flow of pi_k^2/(2 I_k) for a time h: q and pi = (p0, p1, p2) turned about body axis
    k = `axis` (a constant where inlined, so the branches fold away); returns the turned values.
    Scalars, not scratch arrays, so the whole drift of a body stays in registers."""
    if axis == 0:
        momentum = p0
    elif axis == 1:
        momentum = p1
    else:
        momentum = p2
    angle = h * momentum / moment
    c = math.cos(0.5 * angle)
    s = math.sin(0.5 * angle)
    # The double-angle identities from the half angle's: two trig calls instead of four (the drift is the
    # clump step's largest single cost); 1 - 2 s^2 keeps cos accurate for small angles.
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
def _free_rotation(orientations, angular_momenta, principal_moments, i, dt):
    """Body i's orientation after the free rotation for dt (the splitting of the module docstring),
    written back renormalised.  L (world) is left unchanged: the free flow conserves it exactly."""
    w = orientations[i, 0]
    x = orientations[i, 1]
    y = orientations[i, 2]
    z = orientations[i, 3]
    # pi = R(q)^T L, the rows of R as rotation_matrix fills them.
    r00 = 1.0 - 2.0 * (y * y + z * z)
    r01 = 2.0 * (x * y - w * z)
    r02 = 2.0 * (x * z + w * y)
    r10 = 2.0 * (x * y + w * z)
    r11 = 1.0 - 2.0 * (x * x + z * z)
    r12 = 2.0 * (y * z - w * x)
    r20 = 2.0 * (x * z - w * y)
    r21 = 2.0 * (y * z + w * x)
    r22 = 1.0 - 2.0 * (x * x + y * y)
    l0 = angular_momenta[i, 0]
    l1 = angular_momenta[i, 1]
    l2 = angular_momenta[i, 2]
    p0 = r00 * l0 + r10 * l1 + r20 * l2
    p1 = r01 * l0 + r11 * l1 + r21 * l2
    p2 = r02 * l0 + r12 * l1 + r22 * l2
    moment0 = principal_moments[i, 0]
    moment1 = principal_moments[i, 1]
    moment2 = principal_moments[i, 2]
    half = 0.5 * dt
    w, x, y, z, p0, p1, p2 = _principal_rotation(w, x, y, z, p0, p1, p2, 0, moment0, half)
    w, x, y, z, p0, p1, p2 = _principal_rotation(w, x, y, z, p0, p1, p2, 1, moment1, half)
    w, x, y, z, p0, p1, p2 = _principal_rotation(w, x, y, z, p0, p1, p2, 2, moment2, dt)
    w, x, y, z, p0, p1, p2 = _principal_rotation(w, x, y, z, p0, p1, p2, 1, moment1, half)
    w, x, y, z, p0, p1, p2 = _principal_rotation(w, x, y, z, p0, p1, p2, 0, moment0, half)
    # Each factor is a unit quaternion; renormalising stops the norm's round-off random walk.
    norm = math.sqrt(w * w + x * x + y * y + z * z)
    orientations[i, 0] = w / norm
    orientations[i, 1] = x / norm
    orientations[i, 2] = y / norm
    orientations[i, 3] = z / norm


@njit(inline="always", cache=True)
def _store_rotation(orientations, i, rotations):
    """rotations[i] <- R(q_i) (the (n, 3, 3) matrices the members and the loads read)."""
    w = orientations[i, 0]
    x = orientations[i, 1]
    y = orientations[i, 2]
    z = orientations[i, 3]
    rotations[i, 0, 0] = 1.0 - 2.0 * (y * y + z * z)
    rotations[i, 0, 1] = 2.0 * (x * y - w * z)
    rotations[i, 0, 2] = 2.0 * (x * z + w * y)
    rotations[i, 1, 0] = 2.0 * (x * y + w * z)
    rotations[i, 1, 1] = 1.0 - 2.0 * (x * x + z * z)
    rotations[i, 1, 2] = 2.0 * (y * z - w * x)
    rotations[i, 2, 0] = 2.0 * (x * z - w * y)
    rotations[i, 2, 1] = 2.0 * (y * z + w * x)
    rotations[i, 2, 2] = 1.0 - 2.0 * (x * x + y * y)


@njit(inline="always", cache=True)
def _spin_from_momentum(rotations, angular_momenta, principal_moments, i, out):
    """out[i] = omega (world) = R diag(1/I) R^T L with R = rotations[i]."""
    l0 = angular_momenta[i, 0]
    l1 = angular_momenta[i, 1]
    l2 = angular_momenta[i, 2]
    b0 = (rotations[i, 0, 0] * l0 + rotations[i, 1, 0] * l1 + rotations[i, 2, 0] * l2) / principal_moments[i, 0]
    b1 = (rotations[i, 0, 1] * l0 + rotations[i, 1, 1] * l1 + rotations[i, 2, 1] * l2) / principal_moments[i, 1]
    b2 = (rotations[i, 0, 2] * l0 + rotations[i, 1, 2] * l1 + rotations[i, 2, 2] * l2) / principal_moments[i, 2]
    for row in range(3):
        out[i, row] = rotations[i, row, 0] * b0 + rotations[i, row, 1] * b1 + rotations[i, row, 2] * b2


@njit(cache=True)
def drift_bodies(count, positions, velocities, orientations, angular_momenta, principal_moments, dt):
    """x += dt v, and the free rotation of each body for dt (the splitting of the module docstring).

    L (world) is left unchanged: the free flow conserves it exactly.
    """
    for i in range(count):
        for axis in range(3):
            positions[i, axis] += dt * velocities[i, axis]
        _free_rotation(orientations, angular_momenta, principal_moments, i, dt)


@njit(cache=True)
def kick_drift_bodies(count, positions, velocities, orientations, angular_momenta, forces, torques, inverse_masses,
                      principal_moments, gravity, half_dt, dt, rotations, angular_velocities):
    """The step's first half in one pass over the bodies: kick_bodies(dt/2), drift_bodies(dt) (the same
    arithmetic), then rotations[i] = R(q) of the new orientation and omega from L."""
    for i in range(count):
        for axis in range(3):
            velocity = velocities[i, axis] + half_dt * (forces[i, axis] * inverse_masses[i] + gravity[axis])
            velocities[i, axis] = velocity
            angular_momenta[i, axis] += half_dt * torques[i, axis]
            positions[i, axis] += dt * velocity
        _free_rotation(orientations, angular_momenta, principal_moments, i, dt)
        _store_rotation(orientations, i, rotations)
        _spin_from_momentum(rotations, angular_momenta, principal_moments, i, angular_velocities)


@njit(cache=True)
def kick_bodies_and_spin(count, velocities, angular_momenta, forces, torques, inverse_masses, gravity, half_dt,
                         rotations, principal_moments, angular_velocities):
    """The step's second half over the bodies: kick_bodies(dt/2), then omega from L (R = rotations, set
    by this step's drift: the orientation has not changed since)."""
    for i in range(count):
        for axis in range(3):
            velocities[i, axis] += half_dt * (forces[i, axis] * inverse_masses[i] + gravity[axis])
            angular_momenta[i, axis] += half_dt * torques[i, axis]
        _spin_from_momentum(rotations, angular_momenta, principal_moments, i, angular_velocities)


@njit(cache=True)
def body_rotations(count, orientations, rotations):
    """rotations[i] = R(q_i) for every body."""
    for i in range(count):
        _store_rotation(orientations, i, rotations)


@njit(cache=True)
def angular_velocities_from_momenta(count, orientations, angular_momenta, principal_moments, out):
    """out[i] = omega (world) = R diag(1/I) R^T L."""
    rotations = np.empty((count, 3, 3))
    for i in range(count):
        _store_rotation(orientations, i, rotations)
        _spin_from_momentum(rotations, angular_momenta, principal_moments, i, out)


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
def _lever(rotations, b, member_offsets, m, levers):
    """levers[m] = R(q_b) offset_m, the member's centre relative to its body's centre of mass (world)."""
    for axis in range(3):
        levers[m, axis] = (rotations[b, axis, 0] * member_offsets[m, 0] + rotations[b, axis, 1] * member_offsets[m, 1]
                           + rotations[b, axis, 2] * member_offsets[m, 2])


@njit(inline="always", cache=True)
def _member_motion(b, levers, m, body_velocities, body_angular_velocities, out_velocities, out_angular_velocities,
                   row):
    """Row `row` of the outputs: v = v_b + omega x r, spin omega (r = levers[m])."""
    r0 = levers[m, 0]
    r1 = levers[m, 1]
    r2 = levers[m, 2]
    w0 = body_angular_velocities[b, 0]
    w1 = body_angular_velocities[b, 1]
    w2 = body_angular_velocities[b, 2]
    out_velocities[row, 0] = body_velocities[b, 0] + w1 * r2 - w2 * r1
    out_velocities[row, 1] = body_velocities[b, 1] + w2 * r0 - w0 * r2
    out_velocities[row, 2] = body_velocities[b, 2] + w0 * r1 - w1 * r0
    out_angular_velocities[row, 0] = w0
    out_angular_velocities[row, 1] = w1
    out_angular_velocities[row, 2] = w2


@njit(cache=True)
def member_levers(member_count, member_body, member_offsets, rotations, levers):
    """levers[m] = R(q_b) offset_m for every member (rotations: body_rotations)."""
    for m in range(member_count):
        _lever(rotations, member_body[m], member_offsets, m, levers)


@njit(cache=True)
def member_states(member_count, member_body, member_offsets, body_positions, body_velocities, orientations,
                  body_angular_velocities, out_positions, out_velocities, out_angular_velocities):
    """World state of member spheres from their bodies' state.

    member_offsets (m, 3): each member's centre relative to its body's centre of mass, in the body
    principal frame (`shape.MassProperties.member_offsets`).  r = R(q) offset;  x = x_b + r;
    v = v_b + omega x r;  the member spins with its body's omega.  (The step places the members
    with place_members, the same arithmetic straight into the particle rows.)
    """
    rotations = np.empty((orientations.shape[0], 3, 3))
    body_rotations(orientations.shape[0], orientations, rotations)
    levers = np.empty((member_count, 3))
    for m in range(member_count):
        b = member_body[m]
        _lever(rotations, b, member_offsets, m, levers)
        for axis in range(3):
            out_positions[m, axis] = body_positions[b, axis] + levers[m, axis]
        _member_motion(b, levers, m, body_velocities, body_angular_velocities, out_velocities, out_angular_velocities,
                       m)


@njit(cache=True)
def place_members(rows, member_body, member_offsets, rotations, body_positions, body_velocities,
                  body_angular_velocities, levers, positions, velocities, angular_velocities, positions_at_build):
    """member_states written straight into the members' particle rows (rows[m]), keeping each lever
    R(q) offset in levers[m] for the load sum and the second half; returns the largest squared
    displacement of a member since the list build (inf when one is not finite)."""
    largest = 0.0
    for m in range(rows.shape[0]):
        b = member_body[m]
        i = rows[m]
        _lever(rotations, b, member_offsets, m, levers)
        displacement_squared = 0.0
        for axis in range(3):
            positions[i, axis] = body_positions[b, axis] + levers[m, axis]
            offset = positions[i, axis] - positions_at_build[i, axis]
            displacement_squared += offset * offset
        _member_motion(b, levers, m, body_velocities, body_angular_velocities, velocities, angular_velocities, i)
        largest = keep_largest(largest, displacement_squared)
    return largest


@njit(cache=True)
def move_members(rows, member_body, levers, body_velocities, body_angular_velocities, velocities, angular_velocities):
    """The members' velocities and spins after the second half kick (positions and levers unchanged)."""
    for m in range(rows.shape[0]):
        _member_motion(member_body[m], levers, m, body_velocities, body_angular_velocities, velocities,
                       angular_velocities, rows[m])


@njit(inline="always", cache=True)
def _add_member_load(b, levers, m, forces, torques, row, body_forces, body_torques):
    r0 = levers[m, 0]
    r1 = levers[m, 1]
    r2 = levers[m, 2]
    f0 = forces[row, 0]
    f1 = forces[row, 1]
    f2 = forces[row, 2]
    body_forces[b, 0] += f0
    body_forces[b, 1] += f1
    body_forces[b, 2] += f2
    body_torques[b, 0] += r1 * f2 - r2 * f1 + torques[row, 0]
    body_torques[b, 1] += r2 * f0 - r0 * f2 + torques[row, 1]
    body_torques[b, 2] += r0 * f1 - r1 * f0 + torques[row, 2]


@njit(cache=True)
def sum_member_loads(member_count, member_body, member_offsets, orientations, member_forces, member_torques,
                     body_forces, body_torques):
    """Add member loads to their bodies: F_b += f_m;  T_b += r_m x f_m + t_m.

    r_m = R(q) offset is the lever from the centre of mass to the member centre, taken from the
    orientation (not from positions, which may be periodic images).  t_m is the member's own torque
    about its centre (the contact moments r_c x f of its contacts plus rolling torques).  The caller
    zeroes body_forces and body_torques first.  (The step sums with sum_row_loads, the same arithmetic.)
    """
    rotations = np.empty((orientations.shape[0], 3, 3))
    body_rotations(orientations.shape[0], orientations, rotations)
    levers = np.empty((member_count, 3))
    for m in range(member_count):
        b = member_body[m]
        _lever(rotations, b, member_offsets, m, levers)
        _add_member_load(b, levers, m, member_forces, member_torques, m, body_forces, body_torques)


@njit(cache=True)
def sum_row_loads(rows, member_body, levers, forces, torques, body_forces, body_torques):
    """sum_member_loads read straight from the members' particle rows (rows[m]) with the levers
    place_members kept; zeroes body_forces and body_torques first."""
    body_forces[:] = 0.0
    body_torques[:] = 0.0
    for m in range(rows.shape[0]):
        _add_member_load(member_body[m], levers, m, forces, torques, rows[m], body_forces, body_torques)

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


@njit(cache=True)
def kick_bodies(count, velocities, angular_momenta, forces, torques, inverse_masses, gravity, half_dt):
    """v += dt/2 (F/m + g);  L += dt/2 T  (world frame; torques about the centres of mass)."""
    for i in range(count):
        for axis in range(3):
            velocities[i, axis] += half_dt * (forces[i, axis] * inverse_masses[i] + gravity[axis])
            angular_momenta[i, axis] += half_dt * torques[i, axis]


@njit(cache=True)
def _rotate_about_principal_axis(q, body_momentum, axis, principal_moments, i, h):
    """Exact flow of pi_k^2/(2 I_k) for a time h: turn q and pi about body axis k = `axis`."""
    angle = h * body_momentum[axis] / principal_moments[i, axis]
    c = math.cos(0.5 * angle)
    s = math.sin(0.5 * angle)
    # q <- q (x) (c, s e_k): (a1, v1)(a2, v2) = (a1 a2 - v1.v2, a1 v2 + a2 v1 + v1 x v2).
    w, x, y, z = q[0], q[1], q[2], q[3]
    if axis == 0:
        q[0] = w * c - x * s
        q[1] = x * c + w * s
        q[2] = y * c + z * s
        q[3] = z * c - y * s
    elif axis == 1:
        q[0] = w * c - y * s
        q[1] = x * c - z * s
        q[2] = y * c + w * s
        q[3] = z * c + x * s
    else:
        q[0] = w * c - z * s
        q[1] = x * c + y * s
        q[2] = y * c - x * s
        q[3] = z * c + w * s
    # Body frame: d pi/dt = pi x omega with omega = (pi_k / I_k) e_k turns (pi_i, pi_j) by -angle.
    first = (axis + 1) % 3
    second = (axis + 2) % 3
    # The double-angle identities from the half angle's: two trig calls instead of four (the drift is the
    # clump step's largest single cost); 1 - 2 s^2 keeps cos accurate for small angles.
    cos_angle = 1.0 - 2.0 * s * s
    sin_angle = 2.0 * s * c
    a = body_momentum[first]
    b = body_momentum[second]
    body_momentum[first] = cos_angle * a + sin_angle * b
    body_momentum[second] = -sin_angle * a + cos_angle * b


@njit(cache=True)
def drift_bodies(count, positions, velocities, orientations, angular_momenta, principal_moments, dt):
    """x += dt v, and the free rotation of each body for dt (the splitting of the module docstring).

    L (world) is left unchanged: the free flow conserves it exactly.
    """
    rotation = np.empty((3, 3))
    body_momentum = np.empty(3)
    q = np.empty(4)
    half = 0.5 * dt
    for i in range(count):
        for axis in range(3):
            positions[i, axis] += dt * velocities[i, axis]
        for k in range(4):
            q[k] = orientations[i, k]
        rotation_matrix(q[0], q[1], q[2], q[3], rotation)
        for row in range(3):  # pi = R^T L
            body_momentum[row] = (rotation[0, row] * angular_momenta[i, 0] + rotation[1, row] * angular_momenta[i, 1]
                                  + rotation[2, row] * angular_momenta[i, 2])
        _rotate_about_principal_axis(q, body_momentum, 0, principal_moments, i, half)
        _rotate_about_principal_axis(q, body_momentum, 1, principal_moments, i, half)
        _rotate_about_principal_axis(q, body_momentum, 2, principal_moments, i, dt)
        _rotate_about_principal_axis(q, body_momentum, 1, principal_moments, i, half)
        _rotate_about_principal_axis(q, body_momentum, 0, principal_moments, i, half)
        # Each factor is a unit quaternion; renormalising stops the norm's round-off random walk.
        norm = math.sqrt(q[0] * q[0] + q[1] * q[1] + q[2] * q[2] + q[3] * q[3])
        for k in range(4):
            orientations[i, k] = q[k] / norm


@njit(cache=True)
def angular_velocities_from_momenta(count, orientations, angular_momenta, principal_moments, out):
    """out[i] = omega (world) = R diag(1/I) R^T L."""
    rotation = np.empty((3, 3))
    body_omega = np.empty(3)
    for i in range(count):
        rotation_matrix(orientations[i, 0], orientations[i, 1], orientations[i, 2], orientations[i, 3], rotation)
        for row in range(3):
            body_omega[row] = (rotation[0, row] * angular_momenta[i, 0] + rotation[1, row] * angular_momenta[i, 1]
                               + rotation[2, row] * angular_momenta[i, 2]) / principal_moments[i, row]
        for row in range(3):
            out[i, row] = (rotation[row, 0] * body_omega[0] + rotation[row, 1] * body_omega[1]
                           + rotation[row, 2] * body_omega[2])


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


@njit(cache=True)
def member_states(member_count, member_body, member_offsets, body_positions, body_velocities, orientations,
                  body_angular_velocities, out_positions, out_velocities, out_angular_velocities):
    """World state of member spheres from their bodies' state.

    member_offsets (m, 3): each member's centre relative to its body's centre of mass, in the body
    principal frame (`shape.MassProperties.member_offsets`).  r = R(q) offset;  x = x_b + r;
    v = v_b + omega x r;  the member spins with its body's omega.
    """
    rotation = np.empty((3, 3))
    for m in range(member_count):
        b = member_body[m]
        rotation_matrix(orientations[b, 0], orientations[b, 1], orientations[b, 2], orientations[b, 3], rotation)
        r0 = rotation[0, 0] * member_offsets[m, 0] + rotation[0, 1] * member_offsets[m, 1] + rotation[0, 2] * member_offsets[m, 2]
        r1 = rotation[1, 0] * member_offsets[m, 0] + rotation[1, 1] * member_offsets[m, 1] + rotation[1, 2] * member_offsets[m, 2]
        r2 = rotation[2, 0] * member_offsets[m, 0] + rotation[2, 1] * member_offsets[m, 1] + rotation[2, 2] * member_offsets[m, 2]
        w0 = body_angular_velocities[b, 0]
        w1 = body_angular_velocities[b, 1]
        w2 = body_angular_velocities[b, 2]
        out_positions[m, 0] = body_positions[b, 0] + r0
        out_positions[m, 1] = body_positions[b, 1] + r1
        out_positions[m, 2] = body_positions[b, 2] + r2
        out_velocities[m, 0] = body_velocities[b, 0] + w1 * r2 - w2 * r1
        out_velocities[m, 1] = body_velocities[b, 1] + w2 * r0 - w0 * r2
        out_velocities[m, 2] = body_velocities[b, 2] + w0 * r1 - w1 * r0
        out_angular_velocities[m, 0] = w0
        out_angular_velocities[m, 1] = w1
        out_angular_velocities[m, 2] = w2


@njit(cache=True)
def sum_member_loads(member_count, member_body, member_offsets, orientations, member_forces, member_torques,
                     body_forces, body_torques):
    """Add member loads to their bodies: F_b += f_m;  T_b += r_m x f_m + t_m.

    r_m = R(q) offset is the lever from the centre of mass to the member centre, taken from the
    orientation (not from positions, which may be periodic images).  t_m is the member's own torque
    about its centre (the contact moments r_c x f of its contacts plus rolling torques).  The caller
    zeroes body_forces and body_torques first.
    """
    rotation = np.empty((3, 3))
    for m in range(member_count):
        b = member_body[m]
        rotation_matrix(orientations[b, 0], orientations[b, 1], orientations[b, 2], orientations[b, 3], rotation)
        r0 = rotation[0, 0] * member_offsets[m, 0] + rotation[0, 1] * member_offsets[m, 1] + rotation[0, 2] * member_offsets[m, 2]
        r1 = rotation[1, 0] * member_offsets[m, 0] + rotation[1, 1] * member_offsets[m, 1] + rotation[1, 2] * member_offsets[m, 2]
        r2 = rotation[2, 0] * member_offsets[m, 0] + rotation[2, 1] * member_offsets[m, 1] + rotation[2, 2] * member_offsets[m, 2]
        f0 = member_forces[m, 0]
        f1 = member_forces[m, 1]
        f2 = member_forces[m, 2]
        body_forces[b, 0] += f0
        body_forces[b, 1] += f1
        body_forces[b, 2] += f2
        body_torques[b, 0] += r1 * f2 - r2 * f1 + member_torques[m, 0]
        body_torques[b, 1] += r2 * f0 - r0 * f2 + member_torques[m, 1]
        body_torques[b, 2] += r0 * f1 - r1 * f0 + member_torques[m, 2]

"""Rigid-body step for clumps (pdemfem.clumps.rigid_body) against rigid-body mechanics.

Euler's equations of a free body in its principal frame (pi = body angular momentum):
d pi/dt = pi x omega, omega_k = pi_k / I_k; the world angular momentum L = R pi is constant and so
is the energy E = sum pi_k^2/(2 I_k).  References: Landau & Lifshitz, Mechanics, sections 33-37.
"""
from __future__ import annotations

import math

import numpy as np
import pytest

from pdemfem.clumps.quaternion import quaternion_from_axis_angle, rotation_matrices
from pdemfem.clumps.rigid_body import (ROTATION_ROWS, SMALL_HALF_ANGLE, _half_angle_cosine_sine,
                                       angular_momenta_from_velocities, angular_velocities_from_momenta,
                                       body_rotations, drift_bodies, first_half_bodies, index_members,
                                       kick_bodies, kick_bodies_and_spin, kick_drift_bodies, member_levers,
                                       member_states, move_members, place_members, rotation_constants,
                                       rotational_energies, second_half_bodies, sum_body_loads, sum_member_loads,
                                       sum_row_loads)

EPS = np.finfo(float).eps
NO_GRAVITY = np.zeros(3)


def _body(moments, omega_world, orientation=(1.0, 0.0, 0.0, 0.0)):
    orientations = np.array([orientation], dtype=float)
    moments = np.array([moments], dtype=float)
    momenta = np.empty((1, 3))
    angular_momenta_from_velocities(1, orientations, np.array([omega_world], dtype=float), moments, momenta)
    return np.zeros((1, 3)), np.zeros((1, 3)), orientations, momenta, moments


def _body_momentum(orientations, momenta):
    return rotation_matrices(orientations)[0].T @ momenta[0]


def _energy(orientations, momenta, moments):
    out = np.empty(1)
    rotational_energies(1, orientations, momenta, moments, out)
    return out[0]


def complete_elliptic_k(m):
    """K(m) = pi / (2 AGM(1, sqrt(1 - m))), m = k^2 (arithmetic-geometric mean; exact to round-off)."""
    a, b = 1.0, math.sqrt(1.0 - m)
    for _ in range(40):   # quadratic convergence: 6 iterations reach round-off for m <= 1 - 1e-12
        a, b = 0.5 * (a + b), math.sqrt(a * b)
    return math.pi / (2.0 * a)


def test_agm_elliptic_integral_matches_closed_forms():
    """K(0) = pi/2; K(1/2) = Gamma(1/4)^2 / (4 sqrt(pi)) (the lemniscatic case); near m = 1, with k'^2 = 1 - m,
    K = L + k'^2 (L - 1) / 4 + O(k'^4 L), L = ln(4 / k') (Abramowitz & Stegun 17.3.26).  No scipy needed, so
    the check runs wherever the tests do."""
    assert complete_elliptic_k(0.0) == pytest.approx(math.pi / 2, rel=1e-15)  # the AGM of (1, 1): exact
    # math.gamma is good to an ulp or two; the AGM's six rounds to a few: 1e-14 is round-off.
    assert complete_elliptic_k(0.5) == pytest.approx(math.gamma(0.25) ** 2 / (4 * math.sqrt(math.pi)), rel=1e-14)
    for complement in (1e-9, 1e-12):
        m = 1.0 - complement
        k2 = 1.0 - m  # exactly what complete_elliptic_k takes the root of (Sterbenz: the subtraction is exact)
        logarithm = math.log(4.0 / math.sqrt(k2))
        # The series' next term, ~k'^4 L ~ 1e-17, and round-off, ~1e-15 of K ~ 12: 1e-13 relative.
        assert complete_elliptic_k(m) == pytest.approx(logarithm + k2 * (logarithm - 1.0) / 4.0, rel=1e-13)


def flip_period(moments, momentum_squared, energy):
    """Period of Euler's equations (L&L section 37, I1 < I2 < I3): 4 K(k) / rate."""
    i1, i2, i3 = moments
    if momentum_squared > 2.0 * energy * i2:
        k2 = (i2 - i1) * (2 * energy * i3 - momentum_squared) / ((i3 - i2) * (momentum_squared - 2 * energy * i1))
        rate = math.sqrt((i3 - i2) * (momentum_squared - 2 * energy * i1) / (i1 * i2 * i3))
    else:  # the same with the indices 1 and 3 exchanged
        k2 = (i2 - i3) * (2 * energy * i1 - momentum_squared) / ((i1 - i2) * (momentum_squared - 2 * energy * i3))
        rate = math.sqrt((i1 - i2) * (momentum_squared - 2 * energy * i3) / (i1 * i2 * i3))
    return 4.0 * complete_elliptic_k(k2) / rate


def test_free_asymmetric_body_conserves_momentum_and_bounds_energy():
    """1e5 steps of a free asymmetric body tumbling about all three axes."""
    moments = (1.0, 2.0, 3.5)
    q0 = quaternion_from_axis_angle([1.0, 2.0, 3.0], 0.7)
    x, v, q, momenta, moments_array = _body(moments, [0.8, -1.1, 0.6], q0)
    force = np.zeros((1, 3))
    torque = np.zeros((1, 3))
    inverse_mass = np.ones(1)
    omega_max = float(np.linalg.norm(_body_momentum(q, momenta) / moments_array[0]))
    dt = 0.01 / omega_max   # 0.01 rad per step
    steps = 100_000
    momentum0 = momenta.copy()
    energy0 = _energy(q, momenta, moments_array)
    sample_every = 10    # the energy every 10 steps: 1e4 samples resolve the oscillation (period ~600 steps)
    energies = np.empty(steps // sample_every)
    body_norm_error = 0.0
    for n in range(steps):
        kick_bodies(1, v, momenta, force, torque, inverse_mass, NO_GRAVITY, 0.5 * dt)
        drift_bodies(1, x, v, q, momenta, moments_array, dt)
        kick_bodies(1, v, momenta, force, torque, inverse_mass, NO_GRAVITY, 0.5 * dt)
        if n % sample_every == 0:
            energies[n // sample_every] = _energy(q, momenta, moments_array)
        if n % 1000 == 0:
            body_norm_error = max(body_norm_error, abs(np.linalg.norm(_body_momentum(q, momenta)) - np.linalg.norm(momenta)))
    magnitude = np.linalg.norm(momentum0)
    # World L: a free drift never changes it (each sub-flow is exact); bound steps * eps * |L| (round-off
    # of a momentum update per step; the scheme reaches 0).
    assert np.abs(momenta - momentum0).max() <= steps * EPS * magnitude
    # The body-frame |pi| = |R^T L| equals |L| to the rounding of one rotation of a unit quaternion
    # (renormalised each step): 10 eps |L|.
    assert body_norm_error <= 10 * EPS * magnitude
    # Symplectic: E oscillates with amplitude O((omega dt)^2) and does not drift.  Bound (omega dt)^2 E
    # = 1e-4 E (the splitting error per unit time is (omega dt)^2 omega / 12-ish; the modified energy
    # differs from E by that order).  No drift: the mean over the last tenth equals the mean over the first
    # tenth within 1e-2 of the oscillation bound (a first-order or non-symplectic rotor drifts by far more).
    oscillation_bound = (omega_max * dt) ** 2 * energy0
    assert np.abs(energies - energy0).max() <= oscillation_bound
    tenth = len(energies) // 10
    assert abs(energies[-tenth:].mean() - energies[:tenth].mean()) <= 1e-2 * oscillation_bound


def test_intermediate_axis_flip_period():
    """Dzhanibekov: spin near the intermediate axis flips with the L&L period 4 K(k)/rate."""
    moments = (1.0, 2.0, 3.0)
    x, v, q, momenta, moments_array = _body(moments, [0.02, 1.0, 0.02])
    energy = _energy(q, momenta, moments_array)
    period = flip_period(moments, float(momenta[0] @ momenta[0]), energy)   # 34.3 time units, k^2 = 0.9992
    dt = 0.02    # omega dt = 0.02: measured period error 1.7e-5 (4.3e-6 at dt/2: second order)
    crossings = []
    previous = _body_momentum(q, momenta)[1]
    time = 0.0
    for _ in range(int(3.2 * period / dt)):
        drift_bodies(1, x, v, q, momenta, moments_array, dt)
        time += dt
        current = _body_momentum(q, momenta)[1]
        if previous * current < 0.0:   # pi_2 ~ sn changes sign every half period
            crossings.append(time - dt * current / (current - previous))
        previous = current
    assert len(crossings) >= 6
    measured = 2.0 * float(np.mean(np.diff(crossings)))
    # 1 % (the brief's promise); the splitting's phase error is O((omega dt)^2) = 4e-4 times a constant of
    # order one.  Without the gyroscopic term there is no flip at all (pi_2 keeps its sign).
    assert measured == pytest.approx(period, rel=0.01)
    assert measured == pytest.approx(period, rel=(1.0 * dt) ** 2)


def _precession(dt, total_time):
    """Axisymmetric body I1 = I2: rates of omega about the body axis 3 and of the axis 3 about L."""
    i1, i3 = 1.0, 2.5
    omega_perpendicular, omega_3 = 0.6, 1.5
    x, v, q, momenta, moments_array = _body((i1, i1, i3), [omega_perpendicular, 0.0, omega_3])
    steps = int(round(total_time / dt))
    body_phase = np.empty(steps + 1)
    axis_phase = np.empty(steps + 1)
    unit_l = momenta[0] / np.linalg.norm(momenta[0])
    reference = np.cross(unit_l, [0.0, 1.0, 0.0])
    reference /= np.linalg.norm(reference)
    other = np.cross(unit_l, reference)
    for n in range(steps + 1):
        if n:
            drift_bodies(1, x, v, q, momenta, moments_array, dt)
        pi = _body_momentum(q, momenta)
        body_phase[n] = math.atan2(pi[1], pi[0])
        axis = rotation_matrices(q)[0][:, 2]
        axis_phase[n] = math.atan2(axis @ other, axis @ reference)
    body_rate = (np.unwrap(body_phase)[-1] - body_phase[0]) / (steps * dt)
    axis_rate = (np.unwrap(axis_phase)[-1] - axis_phase[0]) / (steps * dt)
    # Euler's equations with I1 = I2: pi_1' = -Omega pi_2, pi_2' = Omega pi_1, so pi_1 + i pi_2 turns about the body axis 3 at
    # Omega = omega_3 (I3 - I1)/I1 (L&L section 36); the symmetry axis precesses about L at |L|/I1 (section 33).
    body_expected = omega_3 * (i3 - i1) / i1
    axis_expected = float(np.linalg.norm(momenta[0])) / i1
    omega_max = math.hypot(omega_perpendicular, omega_3)
    return body_rate, body_expected, axis_rate, axis_expected, omega_max


def test_axisymmetric_precession_rates():
    dt = 0.02
    body_rate, body_expected, axis_rate, axis_expected, omega_max = _precession(dt, 60.0)
    # Verlet-type bound: relative rate error <= (omega_max dt)^2 (second-order splitting, constant < 1).
    bound = (omega_max * dt) ** 2
    assert abs(body_rate / body_expected - 1.0) <= bound
    assert abs(axis_rate / axis_expected - 1.0) <= bound
    # And the error is second order: halving dt cuts it about 4x (3 to 5 allowed for the phase read-out).
    half_body, *_ = _precession(dt / 2, 60.0)
    error, half_error = abs(body_rate - body_expected), abs(half_body - body_expected)
    assert 3.0 <= error / half_error <= 5.0


def test_constant_torque_about_principal_axis_from_rest():
    """w = T t / I exactly: L grows by T dt per step; the body turns about the fixed principal axis.

    The axis of the largest moment: spin about the intermediate axis is unstable (the flip of
    test_intermediate_axis_flip_period) and would amplify the round-off off-axis components.
    """
    moments = (0.3, 0.7, 1.1)
    q0 = quaternion_from_axis_angle([0.2, -1.0, 0.5], 1.3)
    x, v, q, momenta, moments_array = _body(moments, [0.0, 0.0, 0.0], q0)
    axis = rotation_matrices(q)[0][:, 2]             # world direction of principal axis 3
    torque_magnitude = 0.05
    torque = (torque_magnitude * axis)[None, :]
    force = np.zeros((1, 3))
    dt = 1e-3
    steps = 20_000
    for _ in range(steps):
        kick_bodies(1, v, momenta, force, torque, np.ones(1), NO_GRAVITY, 0.5 * dt)
        drift_bodies(1, x, v, q, momenta, moments_array, dt)
        kick_bodies(1, v, momenta, force, torque, np.ones(1), NO_GRAVITY, 0.5 * dt)
    omega = np.empty((1, 3))
    angular_velocities_from_momenta(1, q, momenta, moments_array, omega)
    expected = torque_magnitude * steps * dt / moments[2] * axis
    # Round-off only: 2 steps additions of L (each eps |L|) plus the rotation's eps per step of the axis
    # direction: bound 4 steps eps |omega|.  Using the wrong moment or dropping a half kick fails by > 1e-1.
    assert np.abs(omega[0] - expected).max() <= 4 * steps * EPS * np.linalg.norm(expected)
    assert np.abs(rotation_matrices(q)[0][:, 2] - axis).max() <= 4 * steps * EPS


def test_half_angle_polynomials_are_the_cosine_and_sine_to_round_off():
    """Up to SMALL_HALF_ANGLE the drift takes a sub-rotation's cos and sin of the half angle from
    Taylor polynomials.  The terms they leave out are below 1e-19 there, so they differ from the
    library's (correctly rounded to within an ulp) by the rounding of a few operations: asserted 2 ulp
    of 1 for the cosine and 2 ulp of the sine's value (cutting one more term misses by 1e-14)."""
    for a in np.linspace(-SMALL_HALF_ANGLE, SMALL_HALF_ANGLE, 4001):
        cosine, sine = _half_angle_cosine_sine(a, True)
        assert abs(cosine - math.cos(a)) <= 2 * EPS
        assert abs(sine - math.sin(a)) <= 2 * np.spacing(abs(math.sin(a))) + 1e-300


@pytest.mark.parametrize("turn", [0.01, 1.0])
def test_spin_about_a_principal_axis_turns_by_the_exact_angle(turn):
    """A free spin omega about principal axis 3 is a rotation by omega dt per drift, exactly (the
    other two sub-rotations have pi_k = 0): q = (cos(omega dt/2), 0, 0, sin(omega dt/2)) from the
    identity, to the rounding of q's update and renormalisation (4 eps).  turn = omega dt 0.01 is
    drifted with the polynomials, 1.0 (half angles beyond SMALL_HALF_ANGLE) with math.cos/sin: the
    polynomials there would be off by 5e-9."""
    omega, dt = 3.0, turn / 3.0
    x, v, q, momenta, moments_array = _body((0.3, 0.7, 1.1), [0.0, 0.0, omega])
    momenta_before = momenta.copy()
    drift_bodies(1, x, v, q, momenta, moments_array, dt)
    expected = [math.cos(0.5 * turn), 0.0, 0.0, math.sin(0.5 * turn)]
    assert np.abs(q[0] - expected).max() <= 4 * EPS
    assert np.array_equal(momenta, momenta_before)  # the free flow leaves L alone


def test_member_states_and_loads_are_rigid_body_kinematics():
    rng = np.random.default_rng(3)
    bodies, members = 3, 7
    member_body = np.array([0, 0, 1, 1, 1, 2, 2], dtype=np.int64)
    offsets = rng.normal(size=(members, 3))
    positions = rng.normal(size=(bodies, 3))
    velocities = rng.normal(size=(bodies, 3))
    orientations = np.array([quaternion_from_axis_angle(rng.normal(size=3), rng.uniform(0, 3)) for _ in range(bodies)])
    moments = rng.uniform(0.5, 2.0, size=(bodies, 3))
    omega = rng.normal(size=(bodies, 3))
    momenta = np.empty((bodies, 3))
    angular_momenta_from_velocities(bodies, orientations, omega, moments, momenta)
    omega_back = np.empty((bodies, 3))
    angular_velocities_from_momenta(bodies, orientations, momenta, moments, omega_back)
    assert np.abs(omega_back - omega).max() <= 1e-14 * np.abs(omega).max() * 10   # inverse maps, round-off

    def state(pos, q):
        out_x, out_v, out_w = np.empty((members, 3)), np.empty((members, 3)), np.empty((members, 3))
        member_states(members, member_body, offsets, pos, velocities, q, omega_back, out_x, out_v, out_w)
        return out_x, out_v, out_w

    member_x, member_v, member_w = state(positions, orientations)
    rotation = rotation_matrices(orientations)
    lever = np.einsum("mij,mj->mi", rotation[member_body], offsets)
    assert np.abs(member_x - (positions[member_body] + lever)).max() <= 1e-14 * 10
    assert np.array_equal(member_w, omega_back[member_body])
    # Member velocity = time derivative of member position along the rigid motion (central difference,
    # error h^2 |omega|^3 |r| / 6 ~ 1e-10 at h = 1e-5; round-off 1e-16/h = 1e-11).
    h = 1e-5

    def moved(sign):
        pos = positions + sign * h * velocities
        q = np.array([_compose(quaternion_from_axis_angle(w, sign * h * np.linalg.norm(w)), orientations[b])
                      for b, w in enumerate(omega_back)])
        return state(pos, q)[0]
    derivative = (moved(+1) - moved(-1)) / (2 * h)
    assert np.abs(member_v - derivative).max() <= 1e-8
    # Loads: F = sum f, and power balance sum (f.v + t.w) = F.v + T.w for every rigid motion (virtual work),
    # to round-off.
    member_forces = rng.normal(size=(members, 3))
    member_torques = rng.normal(size=(members, 3))
    body_forces, body_torques = np.zeros((bodies, 3)), np.zeros((bodies, 3))
    sum_member_loads(members, member_body, offsets, orientations, member_forces, member_torques, body_forces, body_torques)
    for b in range(bodies):
        mine = member_body == b
        assert np.abs(body_forces[b] - member_forces[mine].sum(axis=0)).max() <= 1e-14 * 10
        member_power = np.sum(member_forces[mine] * member_v[mine]) + np.sum(member_torques[mine] * member_w[mine])
        body_power = body_forces[b] @ velocities[b] + body_torques[b] @ omega_back[b]
        assert body_power == pytest.approx(member_power, abs=1e-13 * 10)
        # The member torques count: dropping them breaks the balance.
        assert abs(np.sum(member_torques[mine] * member_w[mine])) > 1e-3


def _compose(a, b):
    """Quaternion product a (x) b (b applied first)."""
    w1, v1 = a[0], a[1:]
    w2, v2 = b[0], b[1:]
    return np.concatenate([[w1 * w2 - v1 @ v2], w1 * v2 + w2 * v1 + np.cross(v1, v2)])


def test_stepped_first_half_is_the_per_body_kick_and_drift_bit_for_bit():
    """kick_drift_bodies (the step's kernel: the rotation vectorised over columns, the bodies beyond the
    polynomials' range redone with math.cos and math.sin) gives exactly the values of kick_bodies,
    drift_bodies, body_rotations and angular_velocities_from_momenta one body at a time: the same
    operations in the same order, so equality is exact.  Bodies of every kind mixed: small turns, turns
    beyond SMALL_HALF_ANGLE, a non-finite L; a count no vector width divides."""
    rng = np.random.default_rng(5)
    count, dt, half_dt = 37, 1e-4, 0.5e-4
    gravity = np.array([0.0, 0.0, -9.81])
    orientations = rng.normal(size=(count, 4))
    orientations /= np.linalg.norm(orientations, axis=1)[:, None]
    moments = rng.uniform(1.0, 3.0, size=(count, 3))
    momenta = rng.normal(size=(count, 3))  # |omega| dt / 2 ~ 1e-4: the polynomials
    momenta[[3, 17, 30]] *= 2000.0  # half angles ~ 0.1-0.3 rad: the library functions
    momenta[11, 1] = np.nan
    positions, velocities = rng.normal(size=(count, 3)), rng.normal(size=(count, 3))
    forces, torques = rng.normal(size=(count, 3)), rng.normal(size=(count, 3))
    inverse_masses = rng.uniform(0.5, 2.0, size=count)
    expected = [a.copy() for a in (positions, velocities, orientations, momenta)]
    kick_bodies(count, expected[1], expected[3], forces, torques, inverse_masses, gravity, half_dt)
    drift_bodies(count, expected[0], expected[1], expected[2], expected[3], moments, dt)
    expected_rotations = np.empty((count, 3, 3))
    body_rotations(count, expected[2], expected_rotations)
    expected_spins = np.empty((count, 3))
    angular_velocities_from_momenta(count, expected[2], expected[3], moments, expected_spins)
    rotations, spins = np.empty((count, 3, 3)), np.empty((count, 3))
    kick_drift_bodies(count, positions, velocities, orientations, momenta, forces, torques, inverse_masses, moments,
                      gravity, half_dt, dt, rotations, spins, np.empty((ROTATION_ROWS, count)))
    for got, wanted in zip((positions, velocities, orientations, momenta, rotations, spins),
                           (*expected, expected_rotations, expected_spins)):
        np.testing.assert_array_equal(got, wanted)  # exact (NaN where NaN)
    assert np.isnan(orientations[11]).all() and np.isfinite(np.delete(orientations, 11, axis=0)).all()


def test_step_kernels_in_row_order_are_the_member_kernels_bit_for_bit():
    """The step's kernels reach each member row's body through an index (index_members: row_body, the
    local body of each row) and go over the member rows in row order: first_half_bodies, sum_body_loads,
    second_half_bodies.  They give exactly the values of the member-by-member kernels (kick_bodies +
    drift_bodies, place_members, sum_row_loads, kick_bodies_and_spin + move_members over the member rows
    ascending): the same operations, each body's loads added in the same order.  Bodies of 0 to 3
    members, free rows between the members, body ids not contiguous."""
    rng = np.random.default_rng(11)
    body_ids = np.array([3, 7, 8, 20, 21], dtype=np.int64)
    sizes = [2, 1, 3, 0, 2]
    rows_body = np.concatenate([np.repeat(body_ids, sizes), -np.ones(4, dtype=np.int64)])
    rng.shuffle(rows_body)
    count, rows = len(body_ids), len(rows_body)
    offsets = rng.normal(size=(rows, 3))
    dt, half_dt, gravity = 1e-4, 0.5e-4, np.array([0.0, 0.0, -9.81])
    orientations = rng.normal(size=(count, 4))
    orientations /= np.linalg.norm(orientations, axis=1)[:, None]
    bodies = dict(positions=rng.normal(size=(count, 3)), velocities=rng.normal(size=(count, 3)),
                  orientations=orientations, momenta=rng.normal(size=(count, 3)))
    moments = rng.uniform(1.0, 3.0, size=(count, 3))
    forces, torques = rng.normal(size=(count, 3)), rng.normal(size=(count, 3))
    inverse_masses = rng.uniform(0.5, 2.0, size=count)
    at_build = rng.normal(size=(rows, 3))
    rotations = np.empty((count, 3, 3))
    body_rotations(count, orientations, rotations)

    row_body, levers = np.empty(rows, dtype=np.int64), np.full((rows, 3), 3.0)
    members = index_members(rows, rows_body, offsets, body_ids, rotations, row_body, levers)
    assert members == sum(sizes)
    assert np.array_equal(row_body, np.where(rows_body >= 0, np.searchsorted(body_ids, rows_body), -1))

    # The reference: members in row order, their body by local index.
    reference_rows = np.flatnonzero(rows_body >= 0)
    reference_body = np.searchsorted(body_ids, rows_body[reference_rows])
    reference_offsets = np.ascontiguousarray(offsets[reference_rows])
    reference_levers = np.empty((members, 3))
    member_levers(members, reference_body, reference_offsets, rotations, reference_levers)
    assert np.array_equal(levers[reference_rows], reference_levers)

    old = {name: value.copy() for name, value in bodies.items()}
    kick_bodies(count, old["velocities"], old["momenta"], forces, torques, inverse_masses, gravity, half_dt)
    drift_bodies(count, old["positions"], old["velocities"], old["orientations"], old["momenta"], moments, dt)
    old_rotations, old_spins = np.empty((count, 3, 3)), np.empty((count, 3))
    body_rotations(count, old["orientations"], old_rotations)
    angular_velocities_from_momenta(count, old["orientations"], old["momenta"], moments, old_spins)
    old_rows = [np.full((rows, 3), 5.0) for _ in range(3)]
    old_levers = np.empty((members, 3))
    old_largest = place_members(reference_rows, reference_body, reference_offsets, old_rotations, old["positions"],
                                old["velocities"], old_spins, old_levers, *old_rows, at_build)

    new_rows = [np.full((rows, 3), 5.0) for _ in range(3)]
    spins = np.empty((count, 3))
    used_loads = [np.full((rows, 3), 7.0) for _ in range(2)]
    work = np.empty((ROTATION_ROWS, count))
    rotation_constants(count, moments, dt, work)
    largest = first_half_bodies(count, bodies["positions"], bodies["velocities"], bodies["orientations"],
                                bodies["momenta"], forces, torques, inverse_masses, moments, gravity, 0.0, half_dt, dt,
                                rotations, spins, work, rows, row_body, offsets, levers, *new_rows, at_build,
                                *used_loads)
    member_mask = rows_body >= 0
    for loads in used_loads:  # the members' loads are zeroed for the next evaluation, the free rows' kept
        assert not loads[member_mask].any() and np.all(loads[~member_mask] == 7.0)
    assert largest == old_largest
    for name in bodies:
        assert np.array_equal(bodies[name], old[name])  # exact
    assert np.array_equal(rotations, old_rotations) and np.array_equal(spins, old_spins)
    assert np.array_equal(levers[reference_rows], old_levers)
    assert np.all(levers[~member_mask] == 3.0)  # a free row's lever is not written
    for new, previous in zip(new_rows, old_rows):
        assert np.array_equal(new, previous)  # free rows untouched (5.0) in both

    row_forces, row_torques = rng.normal(size=(rows, 3)), rng.normal(size=(rows, 3))
    old_forces, old_torques = np.full((count, 3), 9.0), np.full((count, 3), 9.0)
    sum_row_loads(reference_rows, reference_body, old_levers, row_forces, row_torques, old_forces, old_torques)
    new_forces, new_torques = np.full((count, 3), 9.0), np.full((count, 3), 9.0)
    sum_body_loads(count, rows, row_body, levers, row_forces, row_torques, new_forces, new_torques)
    assert np.array_equal(new_forces, old_forces) and np.array_equal(new_torques, old_torques)
    assert not new_forces[sizes.index(0)].any()  # a body without members here carries no load

    kick_bodies_and_spin(count, old["velocities"], old["momenta"], old_forces, old_torques, inverse_masses, gravity,
                         half_dt, old_rotations, moments, old_spins)
    move_members(reference_rows, reference_body, old_levers, old["velocities"], old_spins, old_rows[1], old_rows[2])
    second_half_bodies(count, bodies["velocities"], bodies["momenta"], new_forces, new_torques, inverse_masses,
                       gravity, half_dt, rotations, moments, spins, rows, row_body, levers, new_rows[1], new_rows[2])
    assert np.array_equal(bodies["velocities"], old["velocities"]) and np.array_equal(bodies["momenta"], old["momenta"])
    assert np.array_equal(spins, old_spins)
    assert np.array_equal(new_rows[1], old_rows[1]) and np.array_equal(new_rows[2], old_rows[2])


def test_first_half_with_the_pending_load_sum_and_kick_is_the_kernels_in_turn_bit_for_bit():
    """A load sum and second half left pending (ClumpBodies.defer_second_half) are done by the next
    first_half_bodies (pending_half_dt): every array it leaves (bodies and their loads, rotations, omega,
    the member rows' positions, velocities, spins, levers and zeroed loads) is, bit for bit, what
    sum_body_loads, second_half_bodies and then first_half_bodies without a pending kick leave.  The
    pending half step differs from the new one (both are used); the bodies' loads start as stale values
    (the sum overwrites them)."""
    rng = np.random.default_rng(19)
    count, rows = 6, 11
    body_ids = np.arange(count, dtype=np.int64) * 2 + 1
    rows_body = rng.choice(np.concatenate([body_ids, [-1, -1]]), size=rows)
    offsets = rng.normal(size=(rows, 3))
    orientations = rng.normal(size=(count, 4))
    orientations /= np.linalg.norm(orientations, axis=1)[:, None]
    moments = rng.uniform(1.0, 3.0, size=(count, 3))
    bodies = dict(positions=rng.normal(size=(count, 3)), velocities=rng.normal(size=(count, 3)),
                  orientations=orientations, momenta=rng.normal(size=(count, 3)),
                  forces=rng.normal(size=(count, 3)), torques=rng.normal(size=(count, 3)))
    inverse_masses = rng.uniform(0.5, 2.0, size=count)
    gravity, pending_half_dt, half_dt, dt = np.array([0.0, 0.0, -9.81]), 0.6e-4, 0.5e-4, 1e-4
    at_build = rng.normal(size=(rows, 3))
    rotations = np.empty((count, 3, 3))
    body_rotations(count, orientations, rotations)
    row_body, levers = np.empty(rows, dtype=np.int64), np.zeros((rows, 3))
    index_members(rows, rows_body, offsets, body_ids, rotations, row_body, levers)
    spins = np.empty((count, 3))
    angular_velocities_from_momenta(count, orientations, bodies["momenta"], moments, spins)
    row_loads = [rng.normal(size=(rows, 3)) for _ in range(2)]
    row_motion = [rng.normal(size=(rows, 3)) for _ in range(3)]  # positions, velocities, spins
    work = np.empty((ROTATION_ROWS, count))
    rotation_constants(count, moments, dt, work)

    def copies():
        return ({name: value.copy() for name, value in bodies.items()}, rotations.copy(), spins.copy(),
                levers.copy(), [value.copy() for value in row_motion], [value.copy() for value in row_loads])

    def first_half(state, pending):
        body, rotation, spin, lever, motion, loads = state
        return first_half_bodies(count, body["positions"], body["velocities"], body["orientations"], body["momenta"],
                                 body["forces"], body["torques"], inverse_masses, moments, gravity, pending, half_dt,
                                 dt, rotation, spin, work.copy(), rows, row_body, offsets, lever, *motion, at_build,
                                 *loads)

    in_turn = copies()
    body, rotation, spin, lever, motion, loads = in_turn
    sum_body_loads(count, rows, row_body, lever, *loads, body["forces"], body["torques"])
    second_half_bodies(count, body["velocities"], body["momenta"], body["forces"], body["torques"], inverse_masses,
                       gravity, pending_half_dt, rotation, moments, spin, rows, row_body, lever, motion[1], motion[2])
    expected_largest = first_half(in_turn, 0.0)
    merged = copies()
    assert first_half(merged, pending_half_dt) == expected_largest
    for name in bodies:
        assert np.array_equal(merged[0][name], in_turn[0][name]), name
    for got, wanted in zip(merged[1:4] + tuple(merged[4]) + tuple(merged[5]),
                           in_turn[1:4] + tuple(in_turn[4]) + tuple(in_turn[5])):
        assert np.array_equal(got, wanted)
    # the pending sum and kick are done: without them the bodies' loads and velocities differ
    without = copies()
    first_half(without, 0.0)
    for name in ("forces", "velocities"):
        assert not np.array_equal(without[0][name], merged[0][name])


def test_first_half_flags_a_non_finite_member_displacement():
    """first_half_bodies returns inf when a member's displacement is not finite (keep_largest's rule: a
    maximum alone would pass over NaN), here a NaN position at the list build of one member row."""
    count, rows = 2, 3
    row_body = np.array([1, -1, 0], dtype=np.int64)
    moments = np.ones((count, 3))
    work = np.empty((ROTATION_ROWS, count))
    rotation_constants(count, moments, 1e-4, work)
    orientations = np.tile([1.0, 0.0, 0.0, 0.0], (count, 1))
    for at_build_value, expected in ((0.0, None), (np.nan, np.inf)):
        at_build = np.zeros((rows, 3))
        at_build[2, 1] = at_build_value
        largest = first_half_bodies(count, np.ones((count, 3)), np.zeros((count, 3)), orientations.copy(),
                                    np.zeros((count, 3)), np.zeros((count, 3)), np.zeros((count, 3)), np.ones(count),
                                    moments, np.zeros(3), 0.0, 0.5e-4, 1e-4, np.empty((count, 3, 3)),
                                    np.empty((count, 3)), work, rows, row_body, np.zeros((rows, 3)),
                                    np.empty((rows, 3)), *[np.zeros((rows, 3)) for _ in range(3)], at_build,
                                    np.zeros((rows, 3)), np.zeros((rows, 3)))
        if expected is None:
            assert largest == 3.0  # member rows at (1, 1, 1), built at 0; the free row is not counted
        else:
            assert largest == expected


def test_member_index_names_a_member_whose_body_is_not_held():
    """index_members returns -1 - row for the first row whose body id is not among the held ones (the
    caller raises naming that body)."""
    body_ids = np.array([2, 5], dtype=np.int64)
    offsets, rotations = np.zeros((4, 3)), np.tile(np.eye(3), (2, 1, 1))
    buffers = (np.empty(4, dtype=np.int64), np.empty((4, 3)))
    for missing in (4, 9, 0):  # inside, above and below the held ids' span
        body = np.array([5, -1, missing, 2], dtype=np.int64)
        assert index_members(4, body, offsets, body_ids, rotations, *buffers) == -1 - 2
    assert index_members(4, np.array([5, -1, 5, 2], dtype=np.int64), offsets, body_ids, rotations, *buffers) == 3
    assert np.array_equal(buffers[0], [1, -1, 1, 0])

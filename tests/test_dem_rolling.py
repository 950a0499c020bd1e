"""Verification: a sphere sliding into rolling on a plane, and rolling resistance.

Sphere (mass m, I = 2/5 m R^2) on the floor z = 0 under gravity g, moving along +x,
spin w about +y (rolling without slip: v = R w).  The contact-point slip is
s = v - R w.  Friction at the contact, F (along +x), gives

    m dv/dt = F,   I dw/dt = -R F     (torque of F at -R e_z: (-R e_z) x (F e_x) = -R F e_y).

Sliding (s > 0): F = -mu m g, so v = v0 - mu g t and R w = (5/2) mu g t, s = v0 - (7/2) mu g t:
pure rolling begins at t* = 2 v0 / (7 mu g) with v* = v0 - mu g t* = 5/7 v0.

Rolling resistance: a constant torque M = mu_r R* F_n = mu_r R m g opposing w (R* = R
against a wall).  Rolling (dv/dt = R dw/dt):  I dw/dt = -R F - M and F = m dv/dt give
(I/R + m R) dv/dt = -M, i.e.

    a = -M R / (I + m R^2) = -mu_r R^2 m g / (7/5 m R^2) = -(5/7) mu_r g.
"""
from __future__ import annotations

import math

import numpy as np

from mpi_cases.dem_scenes import GLASS, STEEL, effective_modulus, single_sphere_on_floor, sphere_mass
from pdemfem import Simulation

G = 9.81
RADIUS = 1.0e-3


def _resting_overlap(material, wall_material, radius):
    """Hertz static overlap: m g = 4/3 E* sqrt(R) delta^(3/2)."""
    weight = sphere_mass(material, radius) * G
    return (weight / (4.0 / 3.0 * effective_modulus(material, wall_material) * math.sqrt(radius))) ** (2.0 / 3.0)


def _sphere(velocity, spin, mu, mu_r, dt):
    delta = _resting_overlap(GLASS, STEEL, RADIUS)
    scene = single_sphere_on_floor(radius=RADIUS, material=GLASS, wall_material=STEEL, velocity=velocity,
                                   angular_velocity=(0.0, spin, 0.0), height=RADIUS - delta, dt=dt,
                                   restitution=0.5, friction=mu, rolling_friction=mu_r, gravity=(0.0, 0.0, -G),
                                   expected_impact_speed=0.1)
    return Simulation.from_dict(scene), delta


def test_sliding_to_rolling():
    v0, mu = 0.5, 0.3
    t_star = 2.0 * v0 / (7.0 * mu * G)
    dt = t_star / 2000.0
    sim, delta = _sphere((v0, 0.0, 0.0), 0.0, mu, 0.0, dt)
    times, slips, speeds = [0.0], [v0], [v0]
    while slips[-1] > 0.0:
        sim.step(1)
        p = sim.particles
        lever = p.positions[0, 2]  # the engine's lever: centre to contact point, R - delta
        times.append(sim.time)
        slips.append(p.velocities[0, 0] - lever * p.angular_velocities[0, 1])
        speeds.append(p.velocities[0, 0])
        assert sim.time < 2.0 * t_star, "no transition to rolling"
    # s(t) is linear while sliding: interpolating its zero is exact up to round-off.
    fraction = slips[-2] / (slips[-2] - slips[-1])
    t_roll = times[-2] + fraction * (times[-1] - times[-2])
    v_roll = speeds[-2] + fraction * (speeds[-1] - speeds[-2])
    # Error sources: the lever R - delta instead of R changes the slip deceleration
    # mu g (1 + m R'^2 / I) by 5 delta/R / (7/2) ~ 1.4 delta / R and v* by (5/2)(2 delta/R)(2/7)^2... < 1.4 delta/R
    # (delta / R = 3.6e-4 here); the step in which the force switches between the
    # Coulomb cap and the spring is resolved to O(dt / t*) = 5e-4.  Normal force = m g
    # exactly (start at the static overlap).  Tolerance: 2 (1.4 delta/R + dt/t*) = 2e-3.
    tolerance = 2.0 * (1.4 * delta / RADIUS + dt / t_star)
    assert abs(t_roll / t_star - 1.0) < tolerance, (t_roll, t_star)
    assert abs(v_roll / (5.0 / 7.0 * v0) - 1.0) < tolerance, (v_roll, 5.0 / 7.0 * v0)
    # After the transition the sphere keeps rolling at v*: the spring holds (no stick-slip),
    # and with no rolling friction nothing decelerates it.
    sim.step(200)
    p = sim.particles
    assert abs(p.velocities[0, 0] / (5.0 / 7.0 * v0) - 1.0) < tolerance
    assert abs(p.velocities[0, 0] - p.positions[0, 2] * p.angular_velocities[0, 1]) < tolerance * v0


def test_rolling_friction_deceleration():
    v0, mu, mu_r = 0.2, 0.5, 0.05
    deceleration = 5.0 / 7.0 * mu_r * G
    stop_time = v0 / deceleration
    dt = stop_time / 5000.0
    sim, delta = _sphere((v0, 0.0, 0.0), v0 / (RADIUS - delta_guess(RADIUS)), mu, mu_r, dt)
    times, speeds = [], []
    # Sample the first half of the deceleration (far from the stop, where the torque cap acts).
    for _ in range(50):
        sim.step(50)
        times.append(sim.time)
        speeds.append(sim.particles.velocities[0, 0])
    slope, _ = np.polyfit(times, speeds, 1)
    # Error sources: the friction lever R - delta vs the rolling-torque lever R* = R:
    # a = -M R' / (I + m R'^2), relative change < 2 delta / R (7e-4); the tangential
    # spring rings at the contact's tangential period (~1e-4 s), which averages out of
    # a fit over 0.5 s to << 1e-3.  Tolerance 3 delta/R + 1e-3.
    tolerance = 3.0 * delta / RADIUS + 1e-3
    assert abs(-slope / deceleration - 1.0) < tolerance, (slope, -deceleration)
    # Still rolling, not sliding: the contact-point slip stays far below the speed.
    p = sim.particles
    assert abs(p.velocities[0, 0] - p.positions[0, 2] * p.angular_velocities[0, 1]) < 1e-3 * v0
    # And without rolling friction the same sphere does not decelerate (the test can tell).
    free, _ = _sphere((v0, 0.0, 0.0), v0 / (RADIUS - delta), mu, 0.0, dt)
    free.step(500)
    assert abs(free.particles.velocities[0, 0] / v0 - 1.0) < 1e-3


def delta_guess(radius):
    return _resting_overlap(GLASS, STEEL, radius)

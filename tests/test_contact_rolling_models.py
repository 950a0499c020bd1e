"""Rolling resistance models on a slope: the elastic-plastic spring-dashpot (EPSD) holds a sphere at
rest on a slope flatter than mu_r and lets it roll on a steeper one with the limit torque.

A sphere (I = 2/5 m R^2) rolling without slip on a slope of angle theta against the limit moment
M = mu_r R* F_n (R* = R on a wall, F_n = m g cos theta) accelerates at

    a = 5/7 g (sin theta - mu_r cos theta)      (tests/test_dem_rolling.py derives the flat case),

and can rest only if tan theta <= mu_r (the moment of the friction force about the centre,
m g sin theta R, must be held by the rolling spring).
"""
from __future__ import annotations

import math

import numpy as np
import pytest

from mpi_cases.dem_scenes import GLASS, STEEL, effective_modulus, single_sphere_on_floor, sphere_mass
from pdemfem import Simulation

G = 9.81
RADIUS = 1.0e-3
MU_R = 0.1


def _on_slope(tangent, model, tmp_path, end=0.3):
    theta = math.atan(tangent)
    weight = sphere_mass(GLASS, RADIUS) * G * math.cos(theta)
    overlap = (weight / (4.0 / 3.0 * effective_modulus(GLASS, STEEL) * math.sqrt(RADIUS))) ** (2.0 / 3.0)
    # The floor stays z = 0; gravity is tilted by theta (downhill is +x).
    scene = single_sphere_on_floor(radius=RADIUS, material=GLASS, wall_material=STEEL, velocity=(0.0, 0.0, 0.0),
                                   height=RADIUS - overlap, dt="auto", restitution=0.5, friction=0.5,
                                   rolling_friction=MU_R, gravity=(G * math.sin(theta), 0.0, -G * math.cos(theta)),
                                   expected_impact_speed=0.1, end=end)
    scene["interactions"]["default"]["rolling_model"] = model
    return Simulation.from_dict(scene, output_dir=tmp_path), theta


def test_elastic_plastic_rolling_holds_a_sphere_on_a_slope_flatter_than_mu_r(tmp_path):
    sim, theta = _on_slope(0.8 * MU_R, "elastic_plastic", tmp_path)
    start = sim.particles.positions[0].copy()
    sim.step(int(round(0.3 / sim.dt)))
    # At rest: the spring holds the moment; the creep is the spring's elastic deflection only,
    # M / k_r ~ m g sin(theta) R / (2.25 mu_r^2 R^2 S_n) rad, far below a radius.
    travel = np.linalg.norm(sim.particles.positions[0] - start)
    assert travel < 0.01 * RADIUS
    # The dashpot has damped the start-up oscillation: the speed is below 1e-6 of the free-rolling speed
    # the slope would give in the same time (5/7 g sin(theta) t).
    assert np.linalg.norm(sim.particles.velocities[0]) < 1e-6 * 5.0 / 7.0 * G * math.sin(theta) * sim.time


@pytest.mark.parametrize("model", ["elastic_plastic", "constant_torque"])
def test_rolling_down_a_slope_steeper_than_mu_r_at_the_limit_moment(model, tmp_path):
    tangent = 1.5 * MU_R
    sim, theta = _on_slope(tangent, model, tmp_path, end=0.1)
    sim.step(int(round(0.05 / sim.dt)))
    x0, v0, t0 = sim.particles.positions[0, 0], sim.particles.velocities[0, 0], sim.time
    sim.step(int(round(0.05 / sim.dt)))
    acceleration = 2.0 * (sim.particles.positions[0, 0] - x0 - v0 * (sim.time - t0)) / (sim.time - t0) ** 2
    expected = 5.0 / 7.0 * G * (math.sin(theta) - MU_R * math.cos(theta))
    # The lever is R - delta (not R) and the rolling moment uses R* = R: delta / R ~ 1e-3 relative.
    assert acceleration == pytest.approx(expected, rel=5e-3)


def test_elastic_plastic_rolling_energy_balance(tmp_path):
    """Kinetic + rotational + potential + elastic (springs) + dissipated stays constant (the
    Verlet error only): the rolling spring's work and energy are booked consistently."""
    sim, theta = _on_slope(1.5 * MU_R, "elastic_plastic", tmp_path, end=0.1)
    totals = []
    for _ in range(20):
        sim.step(int(round(0.005 / sim.dt)))
        energies = sim.particle_system.energies()
        totals.append(energies["kinetic_energy"] + energies["rotational_energy"] + energies["potential_energy"]
                      + energies["elastic_energy"] + energies["dissipated_energy"])
    scale = sphere_mass(GLASS, RADIUS) * G * RADIUS
    # Verlet's energy error at ~40 steps per contact period is ~1e-4 of the contact's elastic energy
    # (~ m g delta); 1e-4 m g R bounds it with a margin.
    assert max(totals) - min(totals) < 1e-4 * scale


def test_elastic_plastic_rolling_damping_is_the_fraction_of_critical_it_asks():
    """Free rocking of a sphere on a floor below the rolling limit: the rolling spring k_r against the
    sphere's inertia about its contact point, I_c = I + m R^2 = 7/5 m R^2 (it rolls without slip), a damped
    oscillator.  The dashpot eta_r 2 sqrt(I_r k_r) uses that inertia (Ai et
    al. 2011): its damping ratio is eta_r, and the damped period 2 pi sqrt(I_c / k_r) / sqrt(1 - eta_r^2).  (With the sphere's own I = 2/5 m R^2 it was eta_r sqrt(2/7):
    0.160 for the 0.3 asked; LIGGGHTS' epsd model gave 0.299.)"""
    radius, density, modulus, poisson, mu_r, eta_r = 5e-3, 2700.0, 1.0e7, 0.3, 0.05, 0.3
    material = {"density": density, "youngs_modulus": modulus, "poisson_ratio": poisson}
    mass = sphere_mass(material, radius)
    e_star = effective_modulus(material, material)
    overlap = (3.0 * mass * G / (4.0 * e_star * math.sqrt(radius))) ** (2.0 / 3.0)  # Hertz equilibrium
    speed = 5e-5  # the spring's moment stays below mu_r R F_n: k_r speed / (R omega_rocking) < limit
    dt = 1e-5
    scene = single_sphere_on_floor(radius=radius, material=material, velocity=(speed, 0.0, 0.0),
                                   angular_velocity=(0.0, speed / radius, 0.0), height=radius - overlap, dt=dt,
                                   restitution=0.5, friction=0.5, rolling_friction=mu_r, gravity=(0.0, 0.0, -G),
                                   expected_impact_speed=speed, end=0.2)
    scene["interactions"]["default"].update(rolling_model="elastic_plastic", rolling_damping=eta_r)
    sim = Simulation.from_dict(scene)
    times, velocities = [], []
    for _ in range(int(round(0.2 / dt))):
        sim.step(1)
        times.append(sim.time)
        velocities.append(sim.particles.velocities[0, 0])
    velocities = np.array(velocities)
    # Extrema of v_x: every half period, alternating in sign.
    inner = velocities[1:-1]
    peaks = np.flatnonzero((np.abs(inner) >= np.abs(velocities[:-2])) & (np.abs(inner) >= np.abs(velocities[2:])))
    peaks = peaks[np.abs(inner[peaks]) > 1e-3 * speed] + 1
    assert len(peaks) >= 4
    decrement = 2.0 * np.mean(np.log(np.abs(velocities[peaks[:-1]]) / np.abs(velocities[peaks[1:]])))
    ratio = decrement / math.sqrt(4.0 * math.pi ** 2 + decrement ** 2)
    stiffness = 2.25 * (mu_r * radius) ** 2 * 2.0 * e_star * math.sqrt(radius * overlap)  # k_r (S_n = 2 E* a)
    period = 2.0 * np.mean(np.diff(np.array(times)[peaks]))
    # The tangential spring in series with the rolling one softens the rocking by k_r / (S_t R^2) =
    # 2.25 mu_r^2 S_n / S_t ~ 0.7 %; the lever R - delta and the steps (7,800 a period) far less: 2 %.
    undamped = 2.0 * math.pi * math.sqrt(1.4 * mass * radius ** 2 / stiffness)
    assert period == pytest.approx(undamped / math.sqrt(1.0 - eta_r ** 2), rel=0.02)
    assert ratio == pytest.approx(eta_r, rel=0.02)

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

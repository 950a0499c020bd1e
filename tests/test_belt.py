"""Conveyor belts made of a solid: transport_velocity on a solid's contact surface, and the loaded belt.

1. The 2/7 rule (tests/test_conveyor.py derives it) on a deformable solid whose contact surface moves
   with solids[].transport_velocity: a sphere set down at rest slips until t* = 2 V / (7 mu g) and
   then rolls at 2/7 V.
2. A belt span on idlers (node groups by region) under a static load: the idlers' reactions balance
   the belt's weight and the load.
"""
from __future__ import annotations

import math

import numpy as np
import pytest

from mpi_cases.dem_scenes import GLASS, STEEL, effective_modulus, single_sphere_on_floor, sphere_mass
from pdemfem import Simulation

G = 9.81
RADIUS = 1.0e-3
BELT = 0.5
MU = 0.3
# A 1 mm thick layer clamped at its bottom: its sag under its own weight, rho g h^2 / (2 E) ~ 1e-12 m, is
# far below the contact's static overlap (3e-7 m), so the sphere rests on a surface at z = 0.
SOLID = STEEL


def _solid_belt(tmp_path, dt):
    weight = sphere_mass(GLASS, RADIUS) * G
    delta = (weight / (4.0 / 3.0 * effective_modulus(GLASS, SOLID) * math.sqrt(RADIUS))) ** (2.0 / 3.0)
    scene = single_sphere_on_floor(radius=RADIUS, material=GLASS, wall_material=SOLID, velocity=(0.0, 0.0, 0.0),
                                   height=RADIUS - delta, dt=dt, restitution=0.5, friction=MU, rolling_friction=0.0,
                                   gravity=(0.0, 0.0, -G), expected_impact_speed=0.1)
    scene["particles"][0]["insert"]["positions"] = [[0.0013, 0.0007, RADIUS - delta]]
    scene["walls"] = []
    scene["solids"] = [{"name": "belt", "material": "plate", "mesh": {"box": [[-0.01, -0.01, -0.001], [0.01, 0.01, 0.0]],
                                                                      "cells": [2, 2, 1]},
                        "fixed": ["zmin"], "contact": ["zmax"], "transport_velocity": [BELT, 0.0, 0.0]}]
    scene["output"] = {"dir": str(tmp_path / "out")}
    return Simulation.from_dict(scene, base_dir=tmp_path), delta


def test_sphere_on_a_solid_belt_ends_rolling_at_two_sevenths_of_the_belt_speed(tmp_path):
    t_star = 2.0 * BELT / (7.0 * MU * G)
    dt = t_star / 1000.0
    sim, delta = _solid_belt(tmp_path, dt)
    times, slips, speeds = [0.0], [-BELT], [0.0]
    while slips[-1] < 0.0:
        sim.step(1)
        p = sim.particles
        lever = p.positions[0, 2]  # centre to the contact point (the surface stays at z = 0 to ~1e-9 m)
        times.append(sim.time)
        slips.append(p.velocities[0, 0] - lever * p.angular_velocities[0, 1] - BELT)
        speeds.append(p.velocities[0, 0])
        assert sim.time < 2.0 * t_star, "no transition to rolling"
    fraction = slips[-2] / (slips[-2] - slips[-1])
    t_roll = times[-2] + fraction * (times[-1] - times[-2])
    v_roll = speeds[-2] + fraction * (speeds[-1] - speeds[-2])
    # The bound of tests/test_conveyor.py, 2 (1.4 delta/R + dt/t*): the lever R - delta and the step of the
    # slip-to-stick switch.  The solid's surface under the sphere moves by the static sag of a 4 mm
    # 1 mm layer (E = 3e7 Pa) under a 1.0e-4 N weight (~1e-10 m), far below delta (3e-7 m here).
    tolerance = 2.0 * (1.4 * delta / RADIUS + dt / t_star)
    print(f"solid belt: t_roll/t* - 1 = {t_roll / t_star - 1.0:.2e}, v/(2V/7) - 1 = "
          f"{v_roll / (2.0 / 7.0 * BELT) - 1.0:.2e} (tolerance {tolerance:.2e})")
    assert abs(t_roll / t_star - 1.0) < tolerance, (t_roll, t_star)
    assert abs(v_roll / (2.0 / 7.0 * BELT) - 1.0) < tolerance, (v_roll, 2.0 / 7.0 * BELT)
    sim.step(200)
    p = sim.particles
    assert abs(p.velocities[0, 0] / (2.0 / 7.0 * BELT) - 1.0) < tolerance
    assert abs(p.velocities[0, 0] - p.positions[0, 2] * p.angular_velocities[0, 1] - BELT) < tolerance * BELT
    # The belt drive's work (transport only) is booked in wall_work: the kinetic energy it gave plus
    # what friction dissipated while slipping.
    energies = sim.energies()
    assert energies["wall_work"] > energies["kinetic_energy"] + energies["rotational_energy"] > 0.0

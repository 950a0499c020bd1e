"""Verification: heat across the coupled DEM-FEM surface, and the solid's thermo-elastic response.

A hot sphere rests on a cold plate whose material conducts: the contact conducts to the surface
temperature interpolated at the contact point and sends its heat to the same nodes by the same weights,
summed over the FE window and given to the solid over the next advance.  Heat is then conserved across
the interface exactly: what the particles lose (heat_plate, booked per step) is what the plate's nodes
receive, up to the heat still pending in the current FE window (zero at output steps that end a window).
"""
from __future__ import annotations

import numpy as np
import pytest

from pdemfem import Simulation

G = 9.81
GRAIN = {"density": 2500.0, "youngs_modulus": 1.0e7, "poisson_ratio": 0.3, "conductivity": 1.0, "heat_capacity": 0.5}
PLATE = {"density": 2700.0, "youngs_modulus": 7.0e9, "poisson_ratio": 0.33, "conductivity": 200.0,
         "heat_capacity": 0.9, "thermal_expansion": 2.3e-5}


def _scene(tmp_path, fem_every, steps_per_row=20, thermal=None):
    radius = 0.005
    scene = {
        "time": {"end": 0.02},
        "gravity": [0.0, 0.0, -G],
        "materials": {"grain": dict(GRAIN), "plate": dict(PLATE)},
        "interactions": {"default": {"restitution": 0.05, "friction": 0.3}},
        "particles": [{"name": "hot", "material": "grain", "radius": radius, "initial_temperature": 500.0,
                       "insert": {"kind": "list", "positions": [[0.031, 0.029, 0.02 + radius]]}}],
        "solids": [{"name": "plate", "mesh": {"box": [[0, 0, 0], [0.06, 0.06, 0.02]], "cells": [3, 3, 1]},
                    "material": "plate", "fixed": ["xmin", "xmax"], "contact": ["zmax"],
                    "initial_temperature": 300.0, "reference_temperature": 300.0}],
        "coupling": {"fem_every": fem_every},
        "output": {"dir": str(tmp_path / f"out{fem_every}"), "particles": [], "solids": []},
    }
    if thermal is not None:
        scene["solids"][0]["thermal"] = thermal
    return scene


@pytest.mark.parametrize("fem_every", [1, 3])
def test_heat_lost_by_a_hot_particle_is_gained_by_the_plate(tmp_path, fem_every):
    scene = _scene(tmp_path, fem_every)
    sim = Simulation.from_dict(scene)
    plate = sim.solids["plate"]
    assert plate.heat is not None and sim.particle_system.heat
    particle_start = sim.energies()["particle_thermal_energy"]
    plate_start = plate.thermal_energy()
    rows = 0
    for _ in range(12):
        sim.step(fem_every * 40)  # whole FE windows: nothing pending at the comparison
        given = sim.heat_given()["heat_plate"]
        particle = sim.energies()["particle_thermal_energy"]
        plate_heat = plate.thermal_energy()
        # Booked per step from the same numbers that moved the temperatures: the particle's heat content
        # changed by what the plate gave (round-off of C T per step, ~1e-16 of the content each).
        assert particle - particle_start == pytest.approx(given, abs=1e-12 * particle_start)
        # The plate received exactly that, through the nodes (insulated otherwise): sum(Q) * interval per
        # advance, round-off of the plate's content per FE sub-step.
        assert plate_heat - plate_start == pytest.approx(-given, abs=1e-12 * plate_start)
        rows += 1
    assert given < -1e-3 * (particle_start * (500.0 - 300.0) / 500.0)  # heat flowed: not a 0 == 0 test
    temperatures = plate.temperatures
    assert temperatures.max() > 300.0 and temperatures.min() == pytest.approx(300.0, abs=1.0)


def test_hot_particles_make_the_plate_bulge(tmp_path):
    """Thermo-elastic: the heated spot expands; the plate's top rises against a run without heat exchange
    (heat switched off: the same mechanics, temperature uniform at the reference)."""
    heated = Simulation.from_dict(_scene(tmp_path, 1))
    heated.step(600)
    scene = _scene(tmp_path / "cold", 1)
    scene["materials"]["grain"].pop("conductivity")
    scene["heat"] = {"enabled": False}
    cold = Simulation.from_dict(scene)
    cold.step(600)
    lift = heated.solids["plate"].displacements[:, 2] - cold.solids["plate"].displacements[:, 2]
    assert lift.max() > 0.0

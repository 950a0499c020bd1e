"""Verification: a sphere set down at rest on a conveyor belt (a wall with transport_velocity).

The belt's surface moves with V along +x while its geometry stays at z = 0.  The sphere (mass m,
I = 2/5 m R^2, friction mu, no rolling resistance) slips against the belt: the contact point's
velocity relative to the belt is s = v - R w_y - V < 0, so friction F = +mu m g drives it:

    m dv/dt = mu m g,   I dw_y/dt = -R mu m g   ->   v = mu g t,   -R w_y = (5/2) mu g t,
    s = (7/2) mu g t - V:  rolling begins at t* = 2 V / (7 mu g) with v* = mu g t* = 2/7 V.

(The same follows from the angular momentum about the belt line, I w_y + m R v = 0 from rest, which
friction along the line cannot change: rolling, v - R w_y = V gives v = 2/7 V whatever the slip
history.)  Afterwards nothing acts along x: the sphere keeps rolling at 2/7 V.
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


def _resting_overlap(material, wall_material, radius):
    """Hertz static overlap: m g = 4/3 E* sqrt(R) delta^(3/2)."""
    weight = sphere_mass(material, radius) * G
    return (weight / (4.0 / 3.0 * effective_modulus(material, wall_material) * math.sqrt(radius))) ** (2.0 / 3.0)


def _write_square_stl(path, half):
    """Two triangles covering [-half, half]^2 at z = 0, normals +z (ASCII STL)."""
    corners = [(-half, -half, 0.0), (half, -half, 0.0), (half, half, 0.0), (-half, half, 0.0)]
    lines = ["solid belt"]
    for a, b, c in ((0, 1, 2), (0, 2, 3)):
        lines += ["facet normal 0 0 1", "outer loop"]
        lines += [f"vertex {x:.17g} {y:.17g} {z:.17g}" for x, y, z in (corners[a], corners[b], corners[c])]
        lines += ["endloop", "endfacet"]
    lines.append("endsolid belt")
    path.write_text("\n".join(lines) + "\n")


def _belt(kind, tmp_path, dt):
    delta = _resting_overlap(GLASS, STEEL, RADIUS)
    scene = single_sphere_on_floor(radius=RADIUS, material=GLASS, wall_material=STEEL, velocity=(0.0, 0.0, 0.0),
                                   height=RADIUS - delta, dt=dt, restitution=0.5, friction=MU, rolling_friction=0.0,
                                   gravity=(0.0, 0.0, -G), expected_impact_speed=0.1)
    wall = scene["walls"][0]
    if kind == "mesh":
        _write_square_stl(tmp_path / "belt.stl", 0.05)
        wall = {"name": "floor", "kind": "mesh", "file": "belt.stl", "material": "plate"}
    wall["transport_velocity"] = [BELT, 0.0, 0.0]
    scene["walls"] = [wall]
    scene["output"] = {"dir": str(tmp_path / "out")}
    return Simulation.from_dict(scene, base_dir=tmp_path), delta


@pytest.mark.parametrize("kind", ["plane", "mesh"])
def test_sphere_on_a_belt_ends_rolling_at_two_sevenths_of_the_belt_speed(kind, tmp_path):
    t_star = 2.0 * BELT / (7.0 * MU * G)
    dt = t_star / 2000.0
    sim, delta = _belt(kind, tmp_path, dt)
    times, slips, speeds = [0.0], [-BELT], [0.0]
    while slips[-1] < 0.0:
        sim.step(1)
        p = sim.particles
        lever = p.positions[0, 2]  # the engine's lever: centre to contact point, R - delta
        times.append(sim.time)
        slips.append(p.velocities[0, 0] - lever * p.angular_velocities[0, 1] - BELT)
        speeds.append(p.velocities[0, 0])
        assert sim.time < 2.0 * t_star, "no transition to rolling"
    # s(t) is linear while slipping: interpolating its zero is exact up to round-off.
    fraction = slips[-2] / (slips[-2] - slips[-1])
    t_roll = times[-2] + fraction * (times[-1] - times[-2])
    v_roll = speeds[-2] + fraction * (speeds[-1] - speeds[-2])
    # Error sources (as tests/test_dem_rolling.py): the lever R - delta instead of R changes the
    # slip rate (7/2) mu g by (5/2)(2 delta/R)/(7/2) ~ 1.4 delta/R (delta/R = 3.6e-4 here); the step
    # in which friction switches from the Coulomb cap to the spring is resolved to O(dt/t*) = 5e-4;
    # the normal force is m g exactly (set down at the static overlap).  Tolerance 2 (1.4 delta/R + dt/t*).
    tolerance = 2.0 * (1.4 * delta / RADIUS + dt / t_star)
    print(f"{kind} belt: t_roll/t* - 1 = {t_roll / t_star - 1.0:.2e}, v/(2V/7) - 1 = "
          f"{v_roll / (2.0 / 7.0 * BELT) - 1.0:.2e} (tolerance {tolerance:.2e})")
    assert abs(t_roll / t_star - 1.0) < tolerance, (t_roll, t_star)
    assert abs(v_roll / (2.0 / 7.0 * BELT) - 1.0) < tolerance, (v_roll, 2.0 / 7.0 * BELT)
    # Then it keeps rolling at 2/7 V (the spring holds: no stick-slip) with its contact point at the belt speed.
    sim.step(400)
    p = sim.particles
    assert abs(p.velocities[0, 0] / (2.0 / 7.0 * BELT) - 1.0) < tolerance
    assert abs(p.velocities[0, 0] - p.positions[0, 2] * p.angular_velocities[0, 1] - BELT) < tolerance * BELT
    # The geometry did not move: the sphere rests at its static overlap above z = 0.
    assert abs(p.positions[0, 2] - (RADIUS - delta)) < 0.01 * delta
    # The belt drives the sphere: its work is the kinetic energy it gave plus what friction dissipated.
    energies = sim.energies()
    assert energies["wall_work"] > energies["kinetic_energy"] + energies["rotational_energy"] > 0.0


def test_transport_velocity_along_the_normal_is_not_a_surface_motion(tmp_path):
    """Only the part of transport_velocity along the surface moves it: a component along the normal
    would push the sphere off (the normal dashpot); the plane walls drop it (a mesh contact drops it
    at each contact)."""
    sim, _ = _belt("plane", tmp_path, 1e-5)
    walls = sim.particle_system.walls
    walls_velocities = walls.velocities.copy()
    assert np.allclose(walls_velocities, [[BELT, 0.0, 0.0]])
    from pdemfem.walls.plane import PlaneWalls
    from types import SimpleNamespace

    tilted = PlaneWalls([SimpleNamespace(name="w", point=(0, 0, 0), normal=(0, 0, 2), velocity=(0, 0, 0),
                                         material="plate", transport_velocity=(1.0, 0.0, 3.0))], ["plate"])
    assert np.array_equal(tilted.velocities, [[1.0, 0.0, 0.0]])  # the normal part 3 is dropped exactly
    assert np.array_equal(tilted.motion, [[0.0, 0.0, 0.0]])

"""Analytic cylinder walls: overlap, normal and force against the radial geometry."""
from __future__ import annotations

import math

import numpy as np
import pytest

from pdemfem.simulation import Simulation

RADIUS = 0.005
E_STAR = 1.0 / ((1 - 0.25**2) / 1.0e8 + (1 - 0.3**2) / 2.0e11)
AXIS_POINT = np.array([0.1, -0.2, 0.3])
AXIS = np.array([1.0, 2.0, 2.0]) / 3.0


def build(tmp_path, inside, position, velocity=(0, 0, 0), angular_velocity=(0, 0, 0), gravity=(0, 0, 0)):
    wall = {"name": "drum", "kind": "cylinder", "material": "steel", "radius": 0.1, "inside": inside,
            "axis": {"point": AXIS_POINT.tolist(), "direction": (3 * AXIS).tolist()},
            "angular_velocity": list(angular_velocity)}
    data = {
        "time": {"end": 1.0, "dt": 1e-6},
        "gravity": list(gravity),
        "materials": {"glass": {"density": 2500.0, "youngs_modulus": 1.0e8, "poisson_ratio": 0.25},
                      "steel": {"density": 7800.0, "youngs_modulus": 2.0e11, "poisson_ratio": 0.3}},
        "particles": [{"name": "p", "material": "glass", "radius": RADIUS,
                       "insert": {"kind": "list", "positions": [list(map(float, position))],
                                  "velocities": [list(velocity)]}}],
        "walls": [wall],
    }
    return Simulation.from_dict(data, base_dir=tmp_path, output_dir=tmp_path / "out")


def radial_unit():
    # A unit vector normal to the axis.
    radial = np.cross(AXIS, [0.0, 0.0, 1.0])
    return radial / np.linalg.norm(radial)


@pytest.mark.parametrize("inside", [True, False])
def test_overlap_and_force_match_radial_geometry(tmp_path, inside):
    radial = radial_unit()
    overlap = 3.0e-5
    distance = 0.1 - RADIUS + overlap if inside else 0.1 + RADIUS - overlap
    position = AXIS_POINT + 0.37 * AXIS + distance * radial
    sim = build(tmp_path, inside, position)
    force = sim.particle_system.state.forces[0]
    # At rest only the Hertz spring acts: F = 4/3 E* sqrt(R*) delta^1.5 (R* = r inside, the wall convention;
    # r R / (r + R) outside), pointing to the axis inside and away from it outside.  The overlap is a difference of distances from
    # coordinates up to |x| = 0.55 m: two roundings of eps |x| each (the stored position, its offset from the
    # axis point) in 3e-5 m, times 1.5 for delta^1.5: 1.2e-11 of the force (measured 5.3e-13 inside,
    # 9.3e-14 outside) -- far below any geometric mistake.
    contact_radius = RADIUS if inside else RADIUS * 0.1 / (RADIUS + 0.1)
    magnitude = 4.0 / 3.0 * E_STAR * math.sqrt(contact_radius) * overlap**1.5
    expected = magnitude * (-radial if inside else radial)
    round_off = 1.5 * 2.0 * np.finfo(float).eps * np.abs(position).max() / overlap
    np.testing.assert_allclose(force, expected, rtol=0, atol=round_off * magnitude)
    np.testing.assert_allclose(sim.wall_force("drum"), -expected, rtol=0, atol=round_off * magnitude)
    assert sim.contact_count() == 1
    # Torque on the wall about the axis point: the contact point lies on the mantle, the force is radial.
    contact = AXIS_POINT + 0.37 * AXIS + 0.1 * radial
    np.testing.assert_allclose(sim.wall_torque("drum", about=AXIS_POINT), np.cross(contact - AXIS_POINT, -expected),
                               atol=1e-12 * magnitude)


@pytest.mark.parametrize("inside", [True, False])
def test_no_contact_when_clear(tmp_path, inside):
    radial = radial_unit()
    distance = 0.1 - RADIUS - 1e-6 if inside else 0.1 + RADIUS + 1e-6
    sim = build(tmp_path, inside, AXIS_POINT + distance * radial)
    assert sim.contact_count() == 0 and not np.any(sim.particle_system.state.forces)


def test_rotating_drum_drags_particle_along_its_surface(tmp_path):
    radial = radial_unit()
    position = AXIS_POINT + (0.1 - RADIUS + 1e-5) * radial
    omega = 3.0 * AXIS
    sim = build(tmp_path, True, position, angular_velocity=omega)
    sim.step(50)
    velocity = sim.particle_system.state.velocities[0]
    surface_direction = np.cross(AXIS, radial)  # w x r at the contact point
    assert velocity @ surface_direction > 0
    # The tangential drag is along the surface motion (the normal part is the Hertz push inward).
    tangential = velocity - (velocity @ radial) * radial
    # The drag has no axial component: what remains is the round-off of 50 velocity updates and of the
    # projection, a few eps each: 50 x 4 eps = 4.4e-14 of the tangential speed (measured 3.9e-16).
    assert abs(tangential @ AXIS) < 50 * 4 * np.finfo(float).eps * np.linalg.norm(tangential)


def test_an_impact_on_a_thin_post_keeps_the_restitution_at_dt_auto(tmp_path):
    """A 5 mm sphere (E = 1e7) hits a 0.5 mm post head-on at 1 m/s, e = 0.3.  dt auto sized the step for the
    post's R* = r R / (r + R) while the force took R* = r: the contact was 0.6 x as long as planned (55 steps of
    the 89 the restitution rule asks) and the rebound came out 1.1 % low.  With one R* in both, the rebound is
    within the 1 % that dt auto promises."""
    post_radius, speed, restitution = 5e-4, 1.0, 0.3
    scene = {"time": {"end": 1.0, "dt": "auto", "expected_impact_speed": speed}, "gravity": [0, 0, 0],
             "materials": {"soft": {"density": 2500.0, "youngs_modulus": 1.0e7, "poisson_ratio": 0.3}},
             "interactions": {"default": {"restitution": restitution, "friction": 0.0}},
             "particles": [{"name": "p", "material": "soft", "radius": RADIUS,
                            "insert": {"kind": "list", "positions": [[0.0, 0.0, RADIUS + post_radius + 1e-5]],
                                       "velocities": [[0.0, 0.0, -speed]]}}],
             "walls": [{"name": "post", "kind": "cylinder", "material": "soft", "radius": post_radius,
                        "inside": False, "axis": {"point": [0, 0, 0], "direction": [1, 0, 0]}}],
             "output": {"particles": [], "solids": []}}
    sim = Simulation.from_dict(scene, base_dir=tmp_path, output_dir=tmp_path / "out")
    touched = False
    for _ in range(2000):
        sim.step(1)
        touching = sim.contact_count() > 0
        touched = touched or touching
        if touched and not touching:
            break
    assert touched and not touching
    rebound = sim.particle_system.state.velocities[0, 2] / speed
    assert abs(rebound - restitution) < 0.01 * restitution, rebound

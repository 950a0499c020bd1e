"""Scenes and analytic helpers shared by the DEM verification tests (tests/test_dem_*.py)
and the DEM MPI cases (tests/mpi_cases/dem_*.py).

Everything is SI.  The reference formulas (Hertz, restitution) and what each test checks are in
docs/verification.md.
"""
from __future__ import annotations

import math

GLASS = {"density": 2500.0, "youngs_modulus": 1.0e7, "poisson_ratio": 0.3}
STEEL = {"density": 7800.0, "youngs_modulus": 3.0e7, "poisson_ratio": 0.25}


def sphere_mass(material: dict, radius: float) -> float:
    return 4.0 / 3.0 * math.pi * radius**3 * material["density"]


def effective_modulus(a: dict, b: dict) -> float:
    """1/E* = (1 - nu_a^2)/E_a + (1 - nu_b^2)/E_b."""
    return 1.0 / ((1.0 - a["poisson_ratio"] ** 2) / a["youngs_modulus"]
                  + (1.0 - b["poisson_ratio"] ** 2) / b["youngs_modulus"])


def effective_shear_modulus(a: dict, b: dict) -> float:
    """1/G* = 2(2 - nu_a)(1 + nu_a)/E_a + 2(2 - nu_b)(1 + nu_b)/E_b."""
    return 1.0 / sum(2.0 * (2.0 - m["poisson_ratio"]) * (1.0 + m["poisson_ratio"]) / m["youngs_modulus"]
                     for m in (a, b))


def hertz_peak_overlap(m_eff: float, r_eff: float, e_eff: float, speed: float) -> float:
    """delta_max = (15 m* v0^2 / (16 E* sqrt(R*)))^(2/5)."""
    return (15.0 * m_eff * speed**2 / (16.0 * e_eff * math.sqrt(r_eff))) ** 0.4


def hertz_duration(m_eff: float, r_eff: float, e_eff: float, speed: float) -> float:
    """t_c = 2.868 (m*^2 / (R* E*^2 v0))^(1/5)."""
    return 2.868 * (m_eff**2 / (r_eff * e_eff**2 * speed)) ** 0.2


def hertz_duration_exact_factor() -> float:
    """The exact constant behind 2.868: t_c = 2 (delta_max/v0) int_0^1 dx/sqrt(1 - x^(5/2)) (energy
    integral of the undamped Hertz impact) and delta_max/v0 = (15/16)^(2/5) (m*^2/(R* E*^2 v0))^(1/5);
    the integral is (2/5) B(2/5, 1/2)."""
    integral = 0.4 * math.gamma(0.4) * math.gamma(0.5) / math.gamma(0.9)
    return 2.0 * integral * (15.0 / 16.0) ** 0.4


def single_sphere_on_floor(*, radius, material, velocity, angular_velocity=(0.0, 0.0, 0.0), height=None,
                           dt, model="hertz_mindlin", restitution=1.0, friction=0.0, rolling_friction=0.0,
                           normal_stiffness=None, gravity=(0.0, 0.0, 0.0), wall_material=None,
                           expected_impact_speed=None, end=1.0):
    """One sphere above (or resting on) a plane floor z = 0 with normal +z."""
    interaction = {"model": model, "restitution": restitution, "friction": friction,
                   "rolling_friction": rolling_friction}
    if normal_stiffness is not None:
        interaction["normal_stiffness"] = normal_stiffness
    materials = {"ball": dict(material), "plate": dict(wall_material or material)}
    time = {"end": end, "dt": dt}
    if expected_impact_speed is not None:
        time["expected_impact_speed"] = expected_impact_speed
    return {
        "time": time,
        "gravity": list(gravity),
        "materials": materials,
        "interactions": {"default": interaction},
        "particles": [{"name": "ball", "material": "ball", "radius": radius,
                       "insert": {"kind": "list", "positions": [[0.0, 0.0, radius if height is None else height]],
                                  "velocities": [list(velocity)],
                                  "angular_velocities": [list(angular_velocity)]}}],
        "walls": [{"name": "floor", "kind": "plane", "point": [0, 0, 0], "normal": [0, 0, 1],
                   "material": "plate"}],
    }


def two_spheres(*, radii, materials, positions, velocities, dt, model="hertz_mindlin", restitution=1.0,
                friction=0.0, normal_stiffness=None, expected_impact_speed=None, angular_velocities=None,
                extra_particles=(), gravity=(0.0, 0.0, 0.0)):
    """Two spheres (groups 'a' and 'b', ids 0 and 1) with their own materials, no walls.

    extra_particles: further (position, radius) spectators in group 'c' of material 'a'.
    """
    interaction = {"model": model, "restitution": restitution, "friction": friction}
    if normal_stiffness is not None:
        interaction["normal_stiffness"] = normal_stiffness
    time = {"end": 1.0, "dt": dt}
    if expected_impact_speed is not None:
        time["expected_impact_speed"] = expected_impact_speed
    spins = angular_velocities or [(0.0, 0.0, 0.0), (0.0, 0.0, 0.0)]
    groups = [
        {"name": name, "material": name, "radius": radii[k],
         "insert": {"kind": "list", "positions": [list(positions[k])], "velocities": [list(velocities[k])],
                    "angular_velocities": [list(spins[k])]}}
        for k, name in enumerate(("a", "b"))
    ]
    if extra_particles:
        groups.append({"name": "c", "material": "a", "radius": extra_particles[0][1],
                       "insert": {"kind": "list", "positions": [list(p) for p, _ in extra_particles],
                                  "radii": [r for _, r in extra_particles]}})
    return {
        "time": time,
        "gravity": list(gravity),
        "materials": {"a": dict(materials[0]), "b": dict(materials[1])},
        "interactions": {"default": interaction},
        "particles": groups,
        "walls": [],
    }


def box_walls(size, height, material="glass", side_material=None):
    """Floor at z = 0 and four side walls of a size[0] x size[1] box (normals inwards)."""
    lx, ly = size
    side = side_material or material
    return [
        {"name": "floor", "kind": "plane", "point": [0, 0, 0], "normal": [0, 0, 1], "material": material},
        {"name": "x0", "kind": "plane", "point": [0, 0, 0], "normal": [1, 0, 0], "material": side},
        {"name": "x1", "kind": "plane", "point": [lx, 0, 0], "normal": [-1, 0, 0], "material": side},
        {"name": "y0", "kind": "plane", "point": [0, 0, 0], "normal": [0, 1, 0], "material": side},
        {"name": "y1", "kind": "plane", "point": [0, ly, 0], "normal": [0, -1, 0], "material": side},
    ]


DENSE_RADIUS = 1.0e-3


def dense_scene(*, count=200, restitution=0.5, friction=0.4, rolling_friction=0.0, model="hertz_mindlin",
                dt=None, jitter=0.6, seed=3, velocity=(0.0, 0.0, -0.3), radius_spread=0.2):
    """A colliding dense scene: `count` glass spheres (radius 1 mm +- radius_spread) on a jittered
    lattice in a 12 x 12 mm box, thrown down at `velocity` under gravity, with friction and damping.

    dt defaults to 0.2 Rayleigh times of the smallest sphere.
    """
    r = DENSE_RADIUS
    radius = {"min": r * (1.0 - radius_spread), "max": r * (1.0 + radius_spread)} if radius_spread else r
    largest = r * (1.0 + radius_spread)
    lx = ly = 12.0e-3
    if dt is None:
        # 0.2 Rayleigh times (~14 steps per contact), explicit: these scenes test bookkeeping and parallel
        # agreement, not the restitution, and dt auto (>= 30 steps per contact) would double their cost.
        smallest = r * (1.0 - radius_spread)
        shear = GLASS["youngs_modulus"] / (2.0 * (1.0 + GLASS["poisson_ratio"]))
        dt = 0.2 * math.pi * smallest * math.sqrt(GLASS["density"] / shear) / (0.1631 * GLASS["poisson_ratio"] + 0.8766)
    time = {"end": 1.0, "dt": dt}
    return {
        "time": time,
        "gravity": [0.0, 0.0, -9.81],
        "materials": {"glass": dict(GLASS)},
        "interactions": {"default": {"model": model, "restitution": restitution, "friction": friction,
                                     "rolling_friction": rolling_friction}},
        "particles": [{"name": "grains", "material": "glass", "radius": radius,
                       "insert": {"kind": "lattice", "region": {"box": [[0, 0, 0.2e-3], [lx, ly, 60e-3]]},
                                  "count": count, "seed": seed, "jitter": jitter,
                                  "spacing": 2.0 * largest * 1.1, "velocity": list(velocity)}}],
        "walls": box_walls((lx, ly), 60e-3),
    }

"""Verification of the JKR adhesive contact (normal model `jkr`, pdemfem/contact/normal_jkr.py).

Reference (Johnson, Kendall & Roberts 1971; Johnson, Contact Mechanics sec. 5.5), with E*, R* of
the pair and the work of adhesion W:

    delta = a^2/R* - sqrt(2 pi W a / E*),   F = 4 E* a^3 / (3 R*) - sqrt(8 pi W E* a^3),
    zero load: a0^3 = 9 pi W R*^2 / (2 E*), delta0 = a0^2 / (3 R*),
    pull-off under load control: F_c = 3/2 pi W R*;  under displacement control the contact
    breaks at delta_c = -3/4 (pi^2 W^2 R* / E*^2)^(1/3).

Kernel checks compare with these formulas to round-off; the simulations (a sphere stuck to a
plane, two spheres sticking, a sphere hanging under a ceiling) check the equilibrium overlap and
the pull-off force within the 1 % the model promises.
"""
from __future__ import annotations

import math

import numpy as np
import pytest

from pdemfem import Simulation
from pdemfem.contact import layout, normal_jkr

WORK = 0.05          # J/m^2
MODULUS = 1.0e6      # E* [Pa]
SHEAR = 4.0e5        # G* [Pa]
RADIUS = 1.0e-3      # R* [m]


def table(work=WORK, modulus=MODULUS):
    coefficients = np.zeros((1, 1, layout.COLUMNS))
    coefficients[0, 0, layout.EFFECTIVE_MODULUS] = modulus
    coefficients[0, 0, layout.EFFECTIVE_SHEAR_MODULUS] = SHEAR
    coefficients[0, 0, normal_jkr.WORK_OF_ADHESION] = work
    return coefficients


def zero_load_radius(work, modulus, radius):
    return (9.0 * math.pi * work * radius ** 2 / (2.0 * modulus)) ** (1.0 / 3.0)


def pull_off_overlap_analytic(work, modulus, radius):
    return -0.75 * (math.pi ** 2 * work ** 2 * radius / modulus ** 2) ** (1.0 / 3.0)


def test_contact_radius_solves_the_jkr_relation_on_the_whole_stable_branch():
    delta_c = pull_off_overlap_analytic(WORK, MODULUS, RADIUS)
    for overlap in np.concatenate([np.linspace(delta_c, 0.0, 50), np.geomspace(1e-9, 1e-4, 50)]):
        a = normal_jkr.contact_radius(overlap, WORK, MODULUS, RADIUS)
        residual = a * a / RADIUS - math.sqrt(2.0 * math.pi * WORK * a / MODULUS) - overlap
        # Round-off of the closed form: relative to the terms' size a^2/R*.
        assert abs(residual) <= 1e-10 * a * a / RADIUS, overlap
        # The stable branch: a at least the radius where d delta / da = 0.
        a_c = (math.pi * WORK * RADIUS ** 2 / (8.0 * MODULUS)) ** (1.0 / 3.0)
        assert a >= a_c * (1.0 - 1e-6)


def test_zero_load_overlap_pull_off_force_and_break_overlap():
    coefficients = table()
    a0 = zero_load_radius(WORK, MODULUS, RADIUS)
    delta0 = a0 * a0 / (3.0 * RADIUS)
    force, normal_stiffness, tangential_stiffness, _ = normal_jkr.elastic(delta0, coefficients, 0, 0, 1.0, RADIUS)
    pull_off = 1.5 * math.pi * WORK * RADIUS
    assert abs(force) <= 1e-9 * pull_off  # round-off of F's two terms (each ~ F_c)
    assert normal_stiffness == pytest.approx(2.0 * MODULUS * a0, rel=1e-12)
    assert tangential_stiffness == pytest.approx(8.0 * SHEAR * a0, rel=1e-12)
    delta_c = normal_jkr.pull_off_overlap(coefficients, 0, 0, RADIUS)
    assert delta_c == pytest.approx(pull_off_overlap_analytic(WORK, MODULUS, RADIUS), rel=1e-12)
    # The least force on the branch is the load-controlled pull-off -3/2 pi W R*.
    overlaps = np.linspace(delta_c, delta0, 20001)
    forces = np.array([normal_jkr.elastic(d, coefficients, 0, 0, 1.0, RADIUS)[0] for d in overlaps])
    # Sampling error of the minimum: (d delta)^2 F'' ~ 1e-8 relative at 20001 points.
    assert forces.min() == pytest.approx(-pull_off, rel=1e-6)
    # At the break (displacement control) F = -5/6 pi W R* (Johnson 1985, eq. 5.64 with a = a0/36^(1/3)).
    assert forces[0] == pytest.approx(-5.0 / 6.0 * math.pi * WORK * RADIUS, rel=1e-9)
    assert normal_jkr.friction_offset(coefficients, 0, 0, RADIUS) == pytest.approx(2.0 * pull_off, rel=1e-15)


def test_elastic_energy_is_the_potential_of_the_force():
    """Phi(delta) = integral of F from 0: Phi(0) = 0 and dPhi/ddelta = F (central differences)."""
    coefficients = table()
    assert abs(normal_jkr.elastic(0.0, coefficients, 0, 0, 1.0, RADIUS)[3]) <= 1e-12 * WORK * RADIUS ** 2 / RADIUS
    delta_c = normal_jkr.pull_off_overlap(coefficients, 0, 0, RADIUS)
    for overlap in np.linspace(0.9 * delta_c, 5.0 * abs(delta_c), 13):
        step = 1e-4 * abs(delta_c)
        upper = normal_jkr.elastic(overlap + step, coefficients, 0, 0, 1.0, RADIUS)[3]
        lower = normal_jkr.elastic(overlap - step, coefficients, 0, 0, 1.0, RADIUS)[3]
        force = normal_jkr.elastic(overlap, coefficients, 0, 0, 1.0, RADIUS)[0]
        # Central difference: error ~ step^2 F''' ~ 1e-7 of the force scale F_c.
        assert (upper - lower) / (2.0 * step) == pytest.approx(force, abs=1e-6 * 1.5 * math.pi * WORK * RADIUS)
    # What a contact holds when it breaks (the adhesion hysteresis) is positive.
    assert normal_jkr.elastic(delta_c, coefficients, 0, 0, 1.0, RADIUS)[3] > 0.0


MATERIAL = {"density": 1000.0, "youngs_modulus": 1.0e6, "poisson_ratio": 0.3}


def _effective_modulus(count: int) -> float:
    """E* of two bodies of MATERIAL (a sphere on a wall of the same material, or two spheres)."""
    return 1.0 / (count * (1.0 - MATERIAL["poisson_ratio"] ** 2) / MATERIAL["youngs_modulus"])


def _sphere_on_plane(height, gravity, work, restitution=0.2, end=0.05, normal=(0.0, 0.0, 1.0)):
    return {
        "time": {"end": end, "dt": "auto", "expected_impact_speed": 0.05},
        "gravity": list(gravity),
        "materials": {"soft": dict(MATERIAL)},
        "interactions": {"default": {"model": "jkr", "work_of_adhesion": work, "restitution": restitution,
                                     "friction": 0.5}},
        "particles": [{"name": "ball", "material": "soft", "radius": RADIUS,
                       "insert": {"kind": "list", "positions": [[0.0, 0.0, height]]}}],
        "walls": [{"name": "plane", "kind": "plane", "point": [0, 0, 0], "normal": list(normal),
                   "material": "soft"}],
    }


def test_sphere_sticks_to_a_plane_at_the_zero_load_overlap(tmp_path):
    modulus = _effective_modulus(2)
    a0 = zero_load_radius(WORK, modulus, RADIUS)
    delta0 = a0 * a0 / (3.0 * RADIUS)
    # Released just touching, without gravity: adhesion pulls it in, the dashpot settles it.
    sim = Simulation.from_dict(_sphere_on_plane(RADIUS - 1e-3 * delta0, (0.0, 0.0, 0.0), WORK), output_dir=tmp_path)
    sim.run(progress=False)
    overlap = RADIUS - sim.particles.positions[0, 2]
    # The model promises 1 %; the dashpot leaves a residual motion far below that after 0.05 s.
    assert overlap == pytest.approx(delta0, rel=0.01)
    assert abs(sim.particles.velocities[0, 2]) < 1e-3 * delta0 / sim.dt


def test_two_spheres_stick_at_the_zero_load_overlap(tmp_path):
    modulus = _effective_modulus(2)
    radius_effective = RADIUS / 2.0
    a0 = zero_load_radius(WORK, modulus, radius_effective)
    delta0 = a0 * a0 / (3.0 * radius_effective)
    gap = 2.0 * RADIUS + 0.1 * delta0  # apart: insertion refuses overlaps; they close at 2 x 0.01 m/s
    scene = _sphere_on_plane(0.0, (0.0, 0.0, 0.0), WORK)
    scene["walls"] = []
    scene["particles"][0]["insert"] = {"kind": "list", "positions": [[0.0, 0.0, 0.0], [gap, 0.0, 0.0]],
                                       "velocities": [[0.01, 0.0, 0.0], [-0.01, 0.0, 0.0]]}
    sim = Simulation.from_dict(scene, output_dir=tmp_path)
    sim.run(progress=False)
    positions = sim.particles.positions
    overlap = 2.0 * RADIUS - np.linalg.norm(positions[1] - positions[0])
    assert overlap == pytest.approx(delta0, rel=0.01)  # the model's promise
    assert sim.particle_system.contact_count == 1


def _hanging_equilibrium_overlap(weight, modulus):
    """The stable JKR overlap where the adhesion holds `weight` (F = -weight), by bisection on a."""
    def force(a):
        return 4.0 * modulus * a ** 3 / (3.0 * RADIUS) - math.sqrt(8.0 * math.pi * WORK * modulus * a ** 3)
    low = (zero_load_radius(WORK, modulus, RADIUS) ** 3 / 4.0) ** (1.0 / 3.0)  # the force's minimum
    high = zero_load_radius(WORK, modulus, RADIUS)
    for _ in range(200):
        middle = 0.5 * (low + high)
        low, high = (middle, high) if force(middle) < -weight else (low, middle)
    a = 0.5 * (low + high)
    return a * a / RADIUS - math.sqrt(2.0 * math.pi * WORK * a / modulus)


@pytest.mark.parametrize("load_fraction, holds", [(0.99, True), (1.01, False)])
def test_hanging_sphere_comes_off_at_the_pull_off_force(load_fraction, holds, tmp_path):
    """A sphere under a ceiling holds a weight of 0.99 F_c and drops at 1.01 F_c (F_c = 3/2 pi W R*)."""
    modulus = _effective_modulus(2)
    mass = 4.0 / 3.0 * math.pi * RADIUS ** 3 * MATERIAL["density"]
    pull_off = 1.5 * math.pi * WORK * RADIUS
    gravity = load_fraction * pull_off / mass
    if holds:
        overlap = _hanging_equilibrium_overlap(load_fraction * pull_off, modulus)
    else:
        # No equilibrium exists: start where the adhesion is strongest.
        a = (zero_load_radius(WORK, modulus, RADIUS) ** 3 / 4.0) ** (1.0 / 3.0)
        overlap = a * a / RADIUS - math.sqrt(2.0 * math.pi * WORK * a / modulus)
    # Ceiling z = 0 facing down; the sphere hangs below it and gravity pulls it away (-z).  It is placed
    # touching (so the contact forms in the first force evaluation), then moved to the start overlap,
    # which is negative: an adhesive contact holds there only once formed.
    scene = _sphere_on_plane(-(RADIUS - 1e-3 * abs(overlap)), (0.0, 0.0, -gravity), WORK, restitution=0.1,
                             end=0.02, normal=(0.0, 0.0, -1.0))
    sim = Simulation.from_dict(scene, output_dir=tmp_path)
    assert sim.particle_system.contact_count == 1
    sim.particle_system.state.positions[0, 2] = -(RADIUS - overlap)
    # Stepped directly: the run monitor would take the hand-made move for created energy.
    sim.step(int(round(0.02 / sim.dt)))
    gap = -sim.particles.positions[0, 2] - RADIUS
    if holds:
        assert sim.particle_system.contact_count == 1
        assert -gap == pytest.approx(overlap, abs=0.01 * abs(overlap))
    else:
        assert sim.particle_system.contact_count == 0
        assert gap > 10.0 * abs(pull_off_overlap_analytic(WORK, modulus, RADIUS))


def _write_flat_stl(path, half_width, cells):
    """A square z = 0 of 2 cells^2 triangles, normals +z (ASCII STL)."""
    edges = np.linspace(-half_width, half_width, cells + 1)
    lines = ["solid flat"]
    for i in range(cells):
        for j in range(cells):
            a = (edges[i], edges[j], 0.0)
            b = (edges[i + 1], edges[j], 0.0)
            c = (edges[i + 1], edges[j + 1], 0.0)
            d = (edges[i], edges[j + 1], 0.0)
            for triangle in ((a, b, c), (a, c, d)):
                lines.append("facet normal 0 0 1\n outer loop")
                lines += [f"  vertex {x:.9g} {y:.9g} {z:.9g}" for x, y, z in triangle]
                lines.append(" endloop\nendfacet")
    lines.append("endsolid flat")
    path.write_text("\n".join(lines) + "\n")


@pytest.mark.parametrize("kind", ["mesh", "cylinder"])
def test_sphere_sticks_to_mesh_and_cylinder_walls_at_the_zero_load_overlap(kind, tmp_path):
    """The same adhesion through the triangle-mesh and cylinder kernels (a sphere released touching a
    flat triangulated floor, off the triangles' shared edges; inside a drum of radius 1 m, whose
    curvature the wall contact ignores by design)."""
    modulus = _effective_modulus(2)
    a0 = zero_load_radius(WORK, modulus, RADIUS)
    delta0 = a0 * a0 / (3.0 * RADIUS)
    scene = _sphere_on_plane(RADIUS - 1e-3 * delta0, (0.0, 0.0, 0.0), WORK)
    if kind == "mesh":
        _write_flat_stl(tmp_path / "flat.stl", 0.01, 4)
        scene["walls"] = [{"name": "floor", "kind": "mesh", "file": str(tmp_path / "flat.stl"), "material": "soft"}]
        scene["particles"][0]["insert"]["positions"] = [[0.0013, 0.0007, RADIUS - 1e-3 * delta0]]
    else:
        # Drum axis along y through (0, 0, 1 m): its lowest line is z = 0.
        scene["walls"] = [{"name": "drum", "kind": "cylinder", "axis": {"point": [0, 0, 1.0], "direction": [0, 1, 0]},
                           "radius": 1.0, "inside": True, "material": "soft"}]
    sim = Simulation.from_dict(scene, output_dir=tmp_path / "out")
    sim.run(progress=False)
    overlap = RADIUS - sim.particles.positions[0, 2]
    assert overlap == pytest.approx(delta0, rel=0.01)  # the model's promise


def test_check_of_a_jkr_scene_prints_no_numpy_warning(tmp_path, capsys):
    """`pdemfem check` builds the contact table without the particles' radii (for its width and
    composition): the pull-off reach of R* = 0 was 0/0, and numpy's RuntimeWarning reached the user."""
    import warnings

    import yaml

    from pdemfem import cli

    path = tmp_path / "jkr.yaml"
    path.write_text(yaml.safe_dump(_sphere_on_plane(RADIUS, (0.0, 0.0, -9.81), WORK)))
    with warnings.catch_warnings():
        warnings.simplefilter("error")
        assert cli.main(["check", str(path)]) == 0
    assert "RuntimeWarning" not in capsys.readouterr().err

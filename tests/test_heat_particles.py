"""Verification: heat conduction through particle contacts (Batchelor & O'Brien, H = 2 k* a).

The scenes settle their particles (at one temperature, strongly damped) into a mechanical equilibrium
known from Hertz's law, then set the temperatures: every contact's radius a = sqrt(R* delta) -- and
its conductance -- is then known in closed form, and the temperatures follow linear ODEs with exact
solutions.
"""
from __future__ import annotations

import math

import numpy as np
import pytest

from pdemfem import Simulation
from pdemfem.errors import SceneError

G = 9.81
MATERIAL = {"density": 2500.0, "youngs_modulus": 1.0e7, "poisson_ratio": 0.3, "conductivity": 1.0,
            "heat_capacity": 0.1}
FLOOR = {"density": 7800.0, "youngs_modulus": 2.0e9, "poisson_ratio": 0.3, "conductivity": 50.0}


def _modulus(*materials):
    return 1.0 / sum((1.0 - m["poisson_ratio"] ** 2) / m["youngs_modulus"] for m in materials)


def _hertz_overlap(force, modulus, radius):
    """delta with F = 4/3 E* sqrt(R*) delta^(3/2)."""
    return (3.0 * force / (4.0 * modulus * math.sqrt(radius))) ** (2.0 / 3.0)


def _mass(radius, material=MATERIAL):
    return 4.0 / 3.0 * math.pi * radius ** 3 * material["density"]


def _stack_scene(bottom_radius, top_radius, floor_temperature=None, temperatures=(300.0, 300.0), end=0.02):
    """Two spheres stacked on a floor, placed touching (they settle into their Hertz equilibrium)."""
    m1, m2 = _mass(bottom_radius), _mass(top_radius)
    floor_overlap = _hertz_overlap((m1 + m2) * G, _modulus(MATERIAL, FLOOR), bottom_radius)
    pair_radius = bottom_radius * top_radius / (bottom_radius + top_radius)
    pair_overlap = _hertz_overlap(m2 * G, _modulus(MATERIAL, MATERIAL), pair_radius)
    z1 = bottom_radius
    z2 = z1 + bottom_radius + top_radius
    floor = {"name": "floor", "kind": "plane", "material": "floor", "point": [0, 0, 0], "normal": [0, 0, 1]}
    if floor_temperature is not None:
        floor["temperature"] = floor_temperature
    scene = {
        "time": {"end": end},
        "gravity": [0.0, 0.0, -G],
        "materials": {"grain": dict(MATERIAL), "floor": dict(FLOOR)},
        "interactions": {"default": {"restitution": 0.05, "friction": 0.0}},
        "particles": [
            {"name": "bottom", "material": "grain", "radius": bottom_radius, "initial_temperature": temperatures[0],
             "insert": {"kind": "list", "positions": [[0.0, 0.0, z1]]}},
            {"name": "top", "material": "grain", "radius": top_radius, "initial_temperature": temperatures[1],
             "insert": {"kind": "list", "positions": [[0.0, 0.0, z2]]}}],
        "walls": [floor],
        "output": {"particles": []},
    }
    return scene, {"pair_radius": pair_radius, "pair_overlap": pair_overlap, "floor_overlap": floor_overlap,
                   "capacities": (m1 * MATERIAL["heat_capacity"], m2 * MATERIAL["heat_capacity"])}


def _settle(sim, seconds=0.02):
    """Step until the contacts have rung down (e = 0.05: each bounce keeps 0.25 % of the energy)."""
    sim.step(int(round(seconds / sim.dt)))


def _set_temperatures(sim, by_id):
    state = sim.particle_system.state
    state.temperatures[:state.owned_count] = np.asarray(by_id)[state.ids[:state.owned_count]]


def _temperatures_by_id(sim):
    particles = sim.particles
    return particles.temperatures[np.argsort(particles.ids)]


def test_two_particles_relax_to_the_capacity_weighted_mean_at_the_analytic_rate():
    """C1 dT1/dt = H (T2 - T1) = -C2 dT2/dt: the difference decays as exp(-H (1/C1 + 1/C2) t) towards
    (C1 T1 + C2 T2) / (C1 + C2), with H = 2 k a, a = sqrt(R* delta) at the Hertz overlap under the top
    sphere's weight; the floor is adiabatic (no temperature)."""
    scene, known = _stack_scene(1.0e-3, 0.7e-3)
    sim = Simulation.from_dict(scene)
    _settle(sim)
    _set_temperatures(sim, [400.0, 300.0])
    c1, c2 = known["capacities"]
    conductance = 2.0 * MATERIAL["conductivity"] * math.sqrt(known["pair_radius"] * known["pair_overlap"])
    rate = conductance * (1.0 / c1 + 1.0 / c2)
    steps = int(round(1.5 / (rate * sim.dt)))  # 1.5 decay times
    start = _temperatures_by_id(sim)
    content = c1 * start[0] + c2 * start[1]
    sim.step(steps)
    now = _temperatures_by_id(sim)
    # Heat is conserved to round-off: each step moves dt Q between the two, rounded once per particle
    # (|T| ~ 400 K, eps 2.2e-16): the content drifts by at most ~ steps * 2 eps * C T.
    assert abs(c1 * now[0] + c2 * now[1] - content) <= steps * 4.0 * np.finfo(float).eps * content
    # Forward Euler's factor (1 - r dt)^n against exp(-r n dt): ln error n (r dt)^2 / 2 (r dt ~ 1e-3 here),
    # and the contact sits at its equilibrium overlap to round-off (a to 1e-9, checked next).
    measured_rate = -math.log((now[0] - now[1]) / (start[0] - start[1])) / (steps * sim.dt)
    euler_bound = rate * sim.dt  # relative: n (r dt)^2 / 2 / (r n dt) = r dt / 2, doubled
    assert measured_rate == pytest.approx(rate, rel=euler_bound + 1e-6)
    mean = content / (c1 + c2)
    assert (now[0] - mean) * c1 == pytest.approx(-(now[1] - mean) * c2, rel=1e-9)
    positions = sim.particles.positions[np.argsort(sim.particles.ids)]
    gap = positions[1, 2] - positions[0, 2]
    assert 1.7e-3 - gap == pytest.approx(known["pair_overlap"], rel=1e-6)


def test_sphere_on_a_hot_wall_heats_at_the_wall_conductance_and_the_wall_books_the_heat():
    """A single sphere resting on a floor held at 500 K: T -> 500 K as exp(-H_w t / C), H_w = 2 k* a_w
    with k* = 2 k_p k_w / (k_p + k_w), a_w = sqrt(R delta_w); heat_floor equals the particle's gain."""
    radius = 1.0e-3
    scene, known = _stack_scene(radius, 0.7e-3, floor_temperature=500.0, temperatures=(300.0, 300.0))
    scene["particles"] = scene["particles"][:1]  # the bottom sphere alone: re-place it at its own equilibrium
    m1 = _mass(radius)
    overlap = _hertz_overlap(m1 * G, _modulus(MATERIAL, FLOOR), radius)
    sim = Simulation.from_dict(scene)
    _settle(sim)
    _set_temperatures(sim, [300.0])
    heat_before = sim.heat_given()["heat_floor"]
    capacity = m1 * MATERIAL["heat_capacity"]
    k_pair = 2.0 * MATERIAL["conductivity"] * FLOOR["conductivity"] / (MATERIAL["conductivity"] + FLOOR["conductivity"])
    conductance = 2.0 * k_pair * math.sqrt(radius * overlap)
    rate = conductance / capacity
    steps = int(round(1.0 / (rate * sim.dt)))
    sim.step(steps)
    temperature = sim.particles.temperatures[0]
    measured_rate = -math.log((500.0 - temperature) / 200.0) / (steps * sim.dt)
    assert measured_rate == pytest.approx(rate, rel=rate * sim.dt + 1e-6)  # Euler: r dt / 2, doubled
    gained = capacity * (temperature - 300.0)
    # Booked per step as Q dt: the same numbers that moved T, summed (round-off of C T per step).
    assert sim.heat_given()["heat_floor"] - heat_before == pytest.approx(gained, abs=steps * 4 * np.finfo(float).eps * capacity * 500)
    assert sim.energies()["thermal_energy"] == pytest.approx(capacity * temperature, rel=1e-14)


def _chain_scene(count, radius, hot, cold):
    """`count` spheres along x touching each other and two walls at fixed temperatures, no gravity."""
    positions = [[radius + 2.0 * radius * k, 0.0, 0.0] for k in range(count)]
    wall = {"kind": "plane", "material": "floor"}
    return {
        "time": {"end": 1.0},
        "gravity": [0.0, 0.0, 0.0],
        "materials": {"grain": dict(MATERIAL), "floor": dict(FLOOR)},
        "interactions": {"default": {"restitution": 0.05, "friction": 0.0}},
        "particles": [{"name": "chain", "material": "grain", "radius": radius, "initial_temperature": 300.0,
                       "insert": {"kind": "list", "positions": positions}}],
        "walls": [dict(wall, name="hot", point=[0, 0, 0], normal=[1, 0, 0], temperature=hot),
                  dict(wall, name="cold", point=[2.0 * radius * count, 0, 0], normal=[-1, 0, 0],
                       temperature=cold)],
        "output": {"particles": []},
    }


def _compress(sim, wall_name, distance, seconds=0.005):
    """Move a plane wall by `distance` along its normal, then hold it there exactly."""
    walls = sim.particle_system.walls
    index = walls.names.index(wall_name)
    target = walls.points[index] + distance * walls.normals[index]
    steps = int(round(seconds / sim.dt))
    # The plane moves with `motion`; the contact law sees `velocities` (the same here: no conveyor).
    walls.motion[index] = walls.velocities[index] = walls.normals[index] * distance / (steps * sim.dt)
    sim.step(steps)
    walls.motion[index] = walls.velocities[index] = 0.0
    walls.points[index] = target


def test_chain_between_two_walls_reaches_the_series_conductance_profile():
    """Steady state of a chain: one heat flow q through 2 wall contacts and N-1 pair contacts in series,
    q = (T_hot - T_cold) / (2 / H_w + (N - 1) / H_p); T_1 = T_hot - q / H_w, T_k+1 = T_k - q / H_p.
    The cold wall compresses the chain by exactly the overlaps a force F carries (2 delta_w(F) +
    (N - 1) delta_p(F)), so once the chain has rung down every contact carries F."""
    count, radius, force = 5, 1.0e-3, 1.0e-3
    hot, cold = 400.0, 300.0
    wall_overlap = _hertz_overlap(force, _modulus(MATERIAL, FLOOR), radius)
    pair_overlap = _hertz_overlap(force, _modulus(MATERIAL, MATERIAL), radius / 2.0)
    scene = _chain_scene(count, radius, hot, cold)
    k_wall = 2.0 * MATERIAL["conductivity"] * FLOOR["conductivity"] / (MATERIAL["conductivity"] + FLOOR["conductivity"])
    wall_conductance = 2.0 * k_wall * math.sqrt(radius * wall_overlap)
    pair_conductance = 2.0 * MATERIAL["conductivity"] * math.sqrt(radius / 2.0 * pair_overlap)
    flow = (hot - cold) / (2.0 / wall_conductance + (count - 1) / pair_conductance)
    expected = hot - flow / wall_conductance - flow / pair_conductance * np.arange(count)
    # The capacity that makes dt sum(H) / (m c) = 0.25 (stable), so the slowest mode decays in ~100 steps.
    # dt does not depend on the heat capacity: take it from a first build.
    dt = Simulation.from_dict(scene).dt
    scene["materials"]["grain"]["heat_capacity"] = dt * 2.0 * max(wall_conductance, pair_conductance) / (
        0.25 * _mass(radius))
    sim = Simulation.from_dict(scene)
    _compress(sim, "cold", 2.0 * wall_overlap + (count - 1) * pair_overlap)
    _settle(sim)
    _set_temperatures(sim, np.full(count, 300.0))
    sim.step(4000)
    temperatures = _temperatures_by_id(sim)
    # The discrete steady state is the network's exact one (independent of dt); after ~40 decay times of
    # the slowest mode what is left is round-off, and the contacts stay at their equilibrium overlaps
    # (a to ~1e-9: the profile to ~1e-9 of the 100 K drop).
    np.testing.assert_allclose(temperatures, expected, rtol=0, atol=1e-6)
    # The walls book what flows through the chain: the hot wall gives q, the cold one takes it.
    given = sim.heat_given()
    sim.step(1000)
    after = sim.heat_given()
    assert (after["heat_hot"] - given["heat_hot"]) / (1000 * sim.dt) == pytest.approx(flow, rel=1e-6)
    assert (after["heat_cold"] - given["heat_cold"]) / (1000 * sim.dt) == pytest.approx(-flow, rel=1e-6)


def test_heat_off_allocates_no_temperatures_and_writes_none():
    scene, _ = _stack_scene(1.0e-3, 0.7e-3)
    for group in scene["particles"]:
        group.pop("initial_temperature")
    sim = Simulation.from_dict(scene)
    state = sim.particle_system.state
    assert not sim.scene.heat_enabled
    assert state.temperatures is None and state.heat_flows is None
    assert "temperatures" not in state.registry and "heat_flows" not in state.registry
    assert sim.particles.temperatures is None
    assert not any("thermal" in column or column.startswith("heat_") for column in sim.history_columns())


def test_heat_switch_needs_the_material_keys():
    scene, _ = _stack_scene(1.0e-3, 0.7e-3)
    del scene["materials"]["grain"]["heat_capacity"]
    with pytest.raises(SceneError) as error:
        Simulation.from_dict(scene)
    assert "materials.grain" in str(error.value) and "heat_capacity" in str(error.value)
    scene["heat"] = {"enabled": False}
    assert Simulation.from_dict(scene).particle_system.state.temperatures is None


def test_thermal_step_past_the_limit_is_warned_by_check_and_stops_the_run(tmp_path):
    """A heat capacity so small that dt H / (m c) ~ 3 on a hot floor: `check` warns from its estimate, and
    the run stops (SolverError naming the fix) instead of writing oscillating temperatures."""
    from pdemfem.errors import SolverError
    from pdemfem.scene import derived
    from pdemfem.scene.loader import load_scene

    radius = 1.0e-3
    scene, _ = _stack_scene(radius, 0.7e-3, floor_temperature=500.0)
    scene["particles"] = scene["particles"][:1]
    scene["output"] = {"dir": str(tmp_path / "out"), "particles": []}
    scene["time"]["end"] = 0.01
    probe = Simulation.from_dict(scene)
    overlap = _hertz_overlap(_mass(radius) * G, _modulus(MATERIAL, FLOOR), radius)
    k_pair = 2.0 * MATERIAL["conductivity"] * FLOOR["conductivity"] / (MATERIAL["conductivity"] + FLOOR["conductivity"])
    resting_conductance = 2.0 * k_pair * math.sqrt(radius * overlap)
    scene["materials"]["grain"]["heat_capacity"] = probe.dt * resting_conductance / (3.0 * _mass(radius))
    loaded, _ = load_scene(scene)
    assert any("thermal step limit" in warning for warning in derived.warnings(loaded))
    sim = Simulation.from_dict(scene)
    with pytest.raises(SolverError) as error:
        sim.run(progress=False)
    assert "temperature update is unstable" in str(error.value) and "heat_capacity" in str(error.value)
    # With a capacity 10x above the resting limit the same run completes (the guard is not a false alarm).
    scene["materials"]["grain"]["heat_capacity"] *= 10.0
    scene["output"]["dir"] = str(tmp_path / "out2")
    Simulation.from_dict(scene).run(progress=False)


def _estimated_and_measured_ratio(scene, seconds):
    """(`pdemfem check`'s estimate of the largest dt sum(H) / (m c), the run-time guard's measure of it over
    `seconds` of the run, the check's warnings)."""
    from pdemfem.scene import derived
    from pdemfem.scene.loader import load_scene

    loaded, _ = load_scene(scene)
    sim = Simulation.from_dict(scene)
    limit, _ = derived.thermal_step_limit(loaded)
    sim.step(int(round(seconds / sim.dt)))
    sim.energies()  # reduces the guard's running maximum over the ranks
    return sim.dt / limit, sim.particle_system.largest_heat_step_ratio, derived.warnings(loaded)


def test_check_estimates_the_thermal_step_ratio_of_a_sphere_resting_on_a_hot_floor():
    """The estimate takes 12 contacts, one at the overlap of a settling impact (a drop by one diameter: its
    contact radius is 6.7x the resting one here) and 11 pressed by the sphere's weight, where the lone sphere
    has one at rest: 11 + 6.7 = 17.7x the measured ratio.  With c such that the real ratio is 0.014 it does
    not warn (15 contacts at the impact's overlap said 1.4 of the limit: 101x)."""
    scene, _ = _stack_scene(1.0e-3, 0.7e-3, floor_temperature=500.0)
    scene["particles"] = scene["particles"][:1]
    estimate, measured, _ = _estimated_and_measured_ratio(scene, 0.02)
    print(f"lone sphere: estimate {estimate:.4g}, measured {measured:.4g} ({estimate / measured:.3g}x)")
    assert measured <= estimate <= 20.0 * measured
    scene["materials"]["grain"]["heat_capacity"] *= measured / 0.014
    estimate, measured, warnings = _estimated_and_measured_ratio(scene, 0.02)
    assert measured == pytest.approx(0.014, rel=1e-9)
    assert not any("thermal step limit" in warning for warning in warnings), warnings
    assert measured <= estimate < 1.0


def test_check_estimates_the_thermal_step_ratio_of_a_settling_bed_within_a_few_times():
    """350 spheres (radius 1 mm +- 20 %) settle into a ~10-layer bed on a hot floor: the guard's largest ratio
    comes from the impacts while the bed settles onto the pressed bottom layers.  The estimate must stay
    above it (else `check` would pass a run that the guard stops) and be realistic: within 3x (measured
    1.85x; 15 contacts at the impact's overlap gave 8x)."""
    from mpi_cases.dem_scenes import dense_scene

    scene = dense_scene(count=350, velocity=(0.0, 0.0, 0.0))
    scene["materials"]["glass"].update(conductivity=1.0, heat_capacity=5.0e-3)
    scene["particles"][0]["initial_temperature"] = 300.0
    scene["walls"][0]["temperature"] = 400.0
    estimate, measured, _ = _estimated_and_measured_ratio(scene, 0.15)
    print(f"settling bed: estimate {estimate:.4g}, measured {measured:.4g} ({estimate / measured:.3g}x)")
    assert measured > 0.2  # the bed conducts: a real comparison
    assert measured <= estimate <= 3.0 * measured


def test_history_columns_and_plots_of_a_heated_run(tmp_path):
    """history.csv carries the heat columns; pdemfem plot draws temperatures.png and heat.png, and the
    energies figure leaves the heat content out (it would dwarf the mechanical energies)."""
    from pdemfem.plot import plot_history, read_history

    scene, _ = _stack_scene(1.0e-3, 0.7e-3, floor_temperature=500.0, temperatures=(300.0, 350.0), end=0.01)
    scene["output"] = {"dir": str(tmp_path / "out"), "every": 0.001}
    sim = Simulation.from_dict(scene)
    sim.run(progress=False)
    history = read_history(tmp_path / "out" / "history.csv")
    for column in ("thermal_energy", "particle_thermal_energy", "heat_floor", "temperature_particles_min",
                   "temperature_particles_mean", "temperature_particles_max"):
        assert column in history, column
    # The particles' heat content changed by what the floor gave them (round-off of the content per step).
    change = history["particle_thermal_energy"] - history["particle_thermal_energy"][0]
    assert np.allclose(change, history["heat_floor"], rtol=0, atol=1e-12 * history["thermal_energy"][0])
    assert history["temperature_particles_max"][0] == 350.0 and history["temperature_particles_min"][0] == 300.0
    written = {path.name for path in plot_history(tmp_path / "out")}
    assert {"temperatures.png", "heat.png"} <= written
    import h5py

    with h5py.File(tmp_path / "out" / "particles.h5", "r") as handle:
        last = sorted(name for name in handle if name.startswith("step_"))[-1]
        order = np.argsort(handle[last]["ids"][()])
        assert np.array_equal(handle[last]["temperature"][()][order], _temperatures_by_id(sim))


@pytest.mark.parametrize("kind", ["mesh", "cylinder"])
def test_mesh_and_cylinder_walls_conduct_as_the_plane(tmp_path, kind):
    """A sphere resting on a hot flat mesh floor, or at the bottom of a hot horizontal drum (taken flat, R* = r,
    as the cylinder's contact law does), heats exactly as on the plane floor: the same overlap, the same
    conductance, so the same temperatures to round-off (mesh: the flat patch is the plane's distance; the
    drum's bottom point: its distance differs from the plane's by the round-off of the radius arithmetic)."""
    radius = 1.0e-3
    plane, _ = _stack_scene(radius, 0.7e-3, floor_temperature=500.0)
    plane["particles"] = plane["particles"][:1]
    other, _ = _stack_scene(radius, 0.7e-3, floor_temperature=500.0)
    other["particles"] = other["particles"][:1]
    if kind == "mesh":
        (tmp_path / "floor.stl").write_text(
            "solid floor\nfacet normal 0 0 1\nouter loop\nvertex -0.01 -0.01 0\nvertex 0.01 -0.01 0\nvertex 0.01 0.01 0\n"
            "endloop\nendfacet\nfacet normal 0 0 1\nouter loop\nvertex -0.01 -0.01 0\nvertex 0.01 0.01 0\n"
            "vertex -0.01 0.01 0\nendloop\nendfacet\nendsolid floor\n")
        other["walls"] = [{"name": "floor", "kind": "mesh", "material": "floor", "file": str(tmp_path / "floor.stl"),
                           "temperature": 500.0}]
        tolerance = 0.0  # the same numbers in the same order
    else:
        drum = 0.05
        other["walls"] = [{"name": "floor", "kind": "cylinder", "material": "floor", "radius": drum, "inside": True,
                           "axis": {"point": [0.0, 0.0, drum], "direction": [0.0, 1.0, 0.0]}, "temperature": 500.0}]
        tolerance = 1e-9 * 200.0  # distance drum - |rho| rounds at ~1e-16 m of 1e-7 m overlaps: 1e-9 relative
    results = []
    for scene in (plane, other):
        sim = Simulation.from_dict(scene, base_dir=tmp_path)
        sim.step(2000)
        results.append((sim.particles.temperatures[0], sim.heat_given()["heat_floor"]))
    assert results[0][0] > 300.0 + 1.0  # it heated: not a 0 == 0 comparison
    assert abs(results[1][0] - results[0][0]) <= tolerance
    assert results[1][1] == pytest.approx(results[0][1], rel=tolerance / 200.0 + 1e-15)

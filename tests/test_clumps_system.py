"""Rigid clumps in the particle system: equivalence with spheres, verification drops, members that
never touch each other, time step, checkpoints and output (docs/shapes.md)."""
from __future__ import annotations

import math

import h5py
import numpy as np
import pytest

from pdemfem import Simulation
from pdemfem.clumps.bodies import BODY_FIELD
from pdemfem.scene import derived
from pdemfem.scene.loader import load_scene

RADIUS = 1e-3
GLASS = {"density": 2500.0, "youngs_modulus": 1.0e7, "poisson_ratio": 0.25}
EPS = np.finfo(float).eps


def scene(groups, interaction, gravity=(0.0, 0.0, -9.81), walls=True, **extra):
    data = {"time": {"end": 1.0, "dt": "auto"}, "gravity": list(gravity), "materials": {"glass": dict(GLASS)},
            "interactions": {"default": interaction}, "particles": groups,
            "output": {"dir": "out", "every": 1.0, "particles": []}}
    if walls:
        data["walls"] = [{"name": "floor", "kind": "plane", "point": [0, 0, 0], "normal": [0, 0, 1],
                          "material": "glass"}]
    data.update(extra)
    return data


def dumbbell(**clump):
    return {"spheres": [{"position": [-RADIUS, 0, 0], "radius": RADIUS},
                        {"position": [RADIUS, 0, 0], "radius": RADIUS}], **clump}


def build(data, tmp_path, name="out", **keywords):
    return Simulation.from_dict(data, base_dir=tmp_path, output_dir=tmp_path / name, **keywords)


# ------------------------------------------------------------------ a clump of one sphere is a sphere

def one_sphere_scenes(velocities, spins, interaction):
    positions = [[0.0, 0.0, 1.2e-3], [5e-4, 1e-4, 3.6e-3]]
    sphere = {"name": "g", "material": "glass", "radius": RADIUS,
              "insert": {"kind": "list", "positions": positions[:len(velocities)], "velocities": velocities,
                         "angular_velocities": spins}}
    clump = {**sphere, "clump": {"spheres": [{"position": [0, 0, 0], "radius": RADIUS}]}}
    del clump["radius"]
    return scene([sphere], interaction), scene([clump], interaction)


def test_one_sphere_clump_falls_as_the_sphere_bit_for_bit(tmp_path):
    """Translation only (a vertical drop onto the floor, no torque): first_half_bodies and
    second_half_bodies do the sphere integrator's arithmetic on the same numbers (the offset is 0, the
    mass the same), so every bit agrees, through the bounce."""
    sphere_scene, clump_scene = one_sphere_scenes([[0.0, 0.0, -0.1]], [[0.0, 0.0, 0.0]],
                                                  {"model": "hertz_mindlin", "restitution": 0.5, "friction": 0.5})
    sphere, clump = build(sphere_scene, tmp_path, "a"), build(clump_scene, tmp_path, "b")
    assert sphere.dt == clump.dt
    assert np.array_equal(sphere.particle_system.state.mass, clump.particle_system.state.mass)
    touched = False
    for _ in range(40):
        sphere.step(50)
        clump.step(50)
        touched = touched or sphere.contact_count() > 0
        a, b = sphere.particles, clump.particles
        assert np.array_equal(a.positions, b.positions)
        assert np.array_equal(a.velocities, b.velocities)
        assert np.array_equal(b.positions, clump.clumps.positions)
    assert touched and sphere.particles.velocities[0, 2] != 0.0
    assert sphere.energies() == clump.energies()


def test_one_sphere_clump_with_friction_spin_and_a_neighbour_matches_the_sphere_to_round_off(tmp_path):
    """Oblique impacts with friction, rolling resistance and spin: the sphere updates omega += dt/2 T/I,
    the body L += dt/2 T and omega = R diag(1/I) R^T L, which rounds differently (a few eps per step).
    Contacts are dissipative here and carry such differences without growth, so over N steps they stay
    below N eps of each quantity's scale; 4000 steps: 9e-13.  Measured 6e-16 (positions)."""
    interaction = {"model": "hertz_mindlin", "restitution": 0.5, "friction": 0.5, "rolling_friction": 0.1}
    sphere_scene, clump_scene = one_sphere_scenes([[0.05, 0.02, -0.1], [0.0, 0.0, 0.0]],
                                                  [[10.0, -20.0, 30.0], [0.0, 0.0, 0.0]], interaction)
    sphere, clump = build(sphere_scene, tmp_path, "a"), build(clump_scene, tmp_path, "b")
    steps = 4000
    sphere.step(steps)
    clump.step(steps)
    a, b = sphere.particles, clump.particles
    assert np.abs(a.angular_velocities).max() > 1.0  # the friction and the second sphere made it spin
    tolerance = steps * EPS
    assert np.abs(a.positions - b.positions).max() <= tolerance * np.abs(a.positions).max()
    assert np.abs(a.velocities - b.velocities).max() <= tolerance * np.abs(a.velocities).max() + 1e-300
    assert np.abs(a.angular_velocities - b.angular_velocities).max() <= tolerance * np.abs(a.angular_velocities).max()


# ------------------------------------------------------------------ verification drops

def test_dumbbell_dropped_flat_bounces_with_the_restitution_asked_and_stays_flat(tmp_path):
    """Two equal spheres land together: each contact carries the member's mass share M/2, so the body
    bounces like one sphere of mass M/2 with the calibrated damping: e as asked.  Errors: the step
    (dt auto keeps the restitution within 1 % by its own rule, derived.steps_per_contact_required; here
    dt is a tenth of that, so the error is ~0.1 %) and gravity during the contact, g t_c / v = 3e-4."""
    restitution = 0.5
    group = {"name": "d", "material": "glass", "clump": dumbbell(),
             "insert": {"kind": "list", "positions": [[0, 0, 1.02 * RADIUS]], "velocities": [[0, 0, -0.3]]}}
    data = scene([group], {"model": "hertz_mindlin", "restitution": restitution, "friction": 0.5})
    data["materials"]["glass"]["youngs_modulus"] = 6.0e10
    base = float(derived.time_step(load_scene(data)[0]))
    data["time"]["dt"] = base / 10.0
    sim = build(data, tmp_path)
    before = after = None
    for _ in range(100000):
        velocity = float(sim.clumps.velocities[0, 2])
        sim.step(1)
        if sim.contact_count() and before is None:
            before = velocity
        if before is not None and not sim.contact_count():
            after = float(sim.clumps.velocities[0, 2])
            break
    assert after is not None
    measured = -after / before
    print(f"dumbbell flat: restitution {measured:.5f} (asked {restitution})")
    assert abs(measured - restitution) <= 0.01 * restitution
    # Flat: the two contacts are mirror images, so no torque beyond round-off of the forces (~eps F r).
    assert np.abs(sim.clumps.angular_velocities).max() < 1e-9
    assert np.allclose(sim.clumps.orientations[0], [1, 0, 0, 0], rtol=0, atol=1e-12)


def test_dumbbell_dropped_tilted_comes_to_rest_lying_flat(tmp_path):
    """Tilted by 30 degrees and dropped from 1.5 radii: one sphere lands first, the body rocks, slides
    and settles on both spheres.  At rest both member centres are at the height of a sphere resting
    on its share's weight (overlap m g / (2 k) per contact), equal to 1e-3 of the overlap."""
    stiffness = 100.0
    tilt = math.radians(30.0)
    group = {"name": "d", "material": "glass", "clump": dumbbell(),
             "insert": {"kind": "list", "positions": [[0, 0, 3e-3]],
                        "orientations": [[math.cos(tilt / 2), 0, math.sin(tilt / 2), 0]]}}
    sim = build(scene([group], {"model": "linear_spring_dashpot", "restitution": 0.5, "friction": 0.5,
                                "normal_stiffness": stiffness}), tmp_path)
    sim.step(int(0.12 / sim.dt))
    heights = sim.particles.positions[:, 2]
    share = sim.clumps.masses[0] / 2.0
    overlap = share * 9.81 / stiffness
    assert np.allclose(heights, RADIUS - overlap, rtol=0, atol=1e-3 * overlap)
    axis = sim.particles.positions[1] - sim.particles.positions[0]
    assert abs(axis[2]) / np.linalg.norm(axis) < 1e-6
    assert sim.energies()["kinetic_energy"] < 1e-12 * sim.clumps.masses[0] * 9.81 * 3e-3


# ------------------------------------------------------------------ members of one clump

def test_members_of_one_clump_never_interact(tmp_path):
    """Overlapping members (the shape) exert no force on each other: a spinning clump of three
    overlapping spheres in free flight keeps its momentum, the list holds no pair of one body and no
    contact is counted, while two clumps that meet do touch."""
    spheres = [{"position": [0, 0, 0], "radius": RADIUS}, {"position": [1.2 * RADIUS, 0, 0], "radius": RADIUS},
               {"position": [0, 1.2 * RADIUS, 0], "radius": 0.8 * RADIUS}]
    group = {"name": "c", "material": "glass", "clump": {"spheres": spheres},
             "insert": {"kind": "list", "positions": [[0, 0, 0], [6 * RADIUS, 0, 0]],
                        "velocities": [[0.1, 0, 0], [-0.1, 0, 0]], "angular_velocities": [[0, 0, 40.0], [0, 0, 0]]}}
    sim = build(scene([group], {"model": "hertz_mindlin", "restitution": 0.9, "friction": 0.3}, gravity=(0, 0, 0),
                      walls=False), tmp_path)
    state, neighbors = sim.particle_system.state, sim.particle_system.neighbors
    first, second = neighbors.pair_rows()
    body = state.fields[BODY_FIELD]
    assert not np.any(body[first] == body[second])
    assert sim.contact_count() == 0
    momentum = (sim.clumps.masses[:, None] * sim.clumps.velocities).sum(axis=0)
    sim.step(5)
    assert sim.contact_count() == 0
    assert np.array_equal((sim.clumps.masses[:, None] * sim.clumps.velocities).sum(axis=0), momentum)
    touched = 0
    for _ in range(400):
        sim.step(10)
        touched = max(touched, sim.contact_count())
    assert touched > 0  # different clumps do meet
    # Momentum is exchanged pairwise (equal and opposite member forces): conserved to round-off.
    after = (sim.clumps.masses[:, None] * sim.clumps.velocities).sum(axis=0)
    scale = float(sim.clumps.masses[0] * 0.1)
    assert np.abs(after - momentum).max() < 1e-12 * scale


def test_a_clump_leaving_the_domain_is_removed_whole(tmp_path):
    group = {"name": "d", "material": "glass", "clump": dumbbell(),
             "insert": {"kind": "list", "positions": [[0, 0, 0.0], [0, 0, 5e-3]],
                        "velocities": [[2.0, 0, 0], [0, 0, 0]]}}
    data = scene([group], {"model": "hertz_mindlin", "restitution": 0.5}, gravity=(0, 0, 0), walls=False,
                 domain={"box": [[-4e-3, -4e-3, -4e-3], [4e-3, 4e-3, 8e-3]]})
    sim = build(data, tmp_path)
    start = sim.total_energy()
    leaving = 0.5 * sim.clumps.masses[0] * 2.0 ** 2
    for _ in range(200):
        sim.step(20)
        if sim.clumps.ids.size == 1:
            break
    assert list(sim.clumps.ids) == [1]
    assert sim.particle_count() == 2 and sim.particle_system.lost_particles == 2
    # It took its body's kinetic energy out, booked in lost_energy: the total stays (to round-off of its sum).
    energies = sim.energies()
    assert energies["lost_energy"] == pytest.approx(leaving, rel=1e-12)
    assert sim.total_energy() == pytest.approx(start, rel=1e-12)
    np.testing.assert_allclose(np.sort(sim.particles.positions[:, 0]), [-RADIUS, RADIUS], atol=1e-15)
    body = sim.particle_system.state.fields[BODY_FIELD]
    assert list(body[:sim.particle_system.state.owned_count]) == [1, 1]  # the body id


# ------------------------------------------------------------------ time step

def test_dt_auto_resolves_a_contact_on_the_member_mass_share(tmp_path):
    """A dumbbell of given mass 4 m (m: one sphere's mass at the density) puts 2 m on each member (its
    share; the effective mass at a member, M (0.4 r^2 + a^2) / (0.4 r^2 + 2 a^2) = 7/3 m, is larger): dt
    auto equals that of spheres of twice the density.  Computed from the sphere alone it would be the
    step of mass m, sqrt(2) (linear) shorter."""
    sphere_mass = 4.0 / 3.0 * math.pi * RADIUS ** 3 * GLASS["density"]
    interaction = {"model": "linear_spring_dashpot", "restitution": 0.5, "normal_stiffness": 100.0}
    clumps = {"name": "d", "material": "glass", "clump": dumbbell(mass=4.0 * sphere_mass),
              "insert": {"kind": "list", "positions": [[0, 0, 2e-3], [0, 0, 5e-3]]}}
    spheres = {"name": "d", "material": "glass", "radius": RADIUS,
               "insert": {"kind": "list", "positions": [[0, 0, 2e-3], [0, 0, 5e-3]]}}
    dense = scene([spheres], interaction, time={"end": 1.0, "dt": "auto", "dt_factor": 1.0})
    dense["materials"]["glass"]["density"] = 2.0 * GLASS["density"]
    clump_dt = derived.time_step(load_scene(scene([clumps], interaction,
                                                  time={"end": 1.0, "dt": "auto", "dt_factor": 1.0}))[0])
    assert clump_dt == pytest.approx(derived.time_step(load_scene(dense)[0]), rel=1e-12)


# ------------------------------------------------------------------ checkpoints and output

def pile(tmp_path, name, **extra):
    group = {"name": "c", "material": "glass", "clump": {"spheres": [
                {"position": [0, 0, 0], "radius": RADIUS}, {"position": [1.3 * RADIUS, 0, 0], "radius": 0.8 * RADIUS},
                {"position": [0, 0, 1.3 * RADIUS], "radius": 0.7 * RADIUS}]},
             "insert": {"kind": "random", "count": 10, "seed": 4, "velocity": [0.0, 0.0, -1.0],
                        "region": {"box": [[-5e-3, -5e-3, 0.0], [5e-3, 5e-3, 8e-3]]}}}
    data = scene([group], {"model": "hertz_mindlin", "restitution": 0.4, "friction": 0.5}, **extra)
    data["walls"] += [{"name": f"side{k}", "kind": "plane", "point": point, "normal": normal, "material": "glass"}
                      for k, (point, normal) in enumerate([([-6e-3, 0, 0], [1, 0, 0]), ([6e-3, 0, 0], [-1, 0, 0]),
                                                          ([0, -6e-3, 0], [0, 1, 0]), ([0, 6e-3, 0], [0, -1, 0])])]
    return data


def body_state(sim):
    c = sim.clumps
    p = sim.particles
    order = np.argsort(p.ids)
    return {"positions": c.positions, "orientations": c.orientations, "velocities": c.velocities,
            "angular_velocities": c.angular_velocities, "member_positions": p.positions[order],
            "member_velocities": p.velocities[order]}


def test_restart_from_a_checkpoint_amid_collisions_is_bit_identical(tmp_path):
    """Ten 3-sphere clumps thrown onto a floor; checkpoints every 200 steps, restarted from step 400
    (the clumps touch the floor and each other there) and run to 600: every bit as the uninterrupted run."""
    data = pile(tmp_path, "run")
    dt = build(data, tmp_path, "probe").dt
    data["time"]["end"] = 600 * dt
    data["checkpoint"] = {"every": 200 * dt, "keep": 5}
    data["output"]["every"] = 200 * dt
    full = build(data, tmp_path, "full")
    full.run(progress=False)
    assert full.step_count == 600
    checkpoint = tmp_path / "full" / "checkpoints" / "checkpoint_000000000400.h5"
    restarted = build(data, tmp_path, "full", restart=checkpoint)
    assert restarted.step_count == 400 and restarted.contact_count() > 0
    restarted.run(progress=False)
    a, b = body_state(full), body_state(restarted)
    for key in a:
        assert np.array_equal(a[key], b[key]), key


def test_clump_series_holds_positions_and_orientations(tmp_path):
    data = pile(tmp_path, "run")
    data["time"]["end"] = 1e-4
    data["output"] = {"dir": "out", "every": 5e-5, "particles": ["positions", "ids"]}
    sim = build(data, tmp_path, "out")
    sim.run(progress=False)
    with h5py.File(tmp_path / "out" / "clumps.h5", "r") as handle:
        steps = sorted(key for key in handle if key.startswith("step_"))
        last = handle[steps[-1]]
        assert last["orientations"].shape == (10, 4)
        order = np.argsort(last["ids"][()])
        assert np.array_equal(last["positions"][()][order], sim.clumps.positions)
        assert np.array_equal(last["orientations"][()][order], sim.clumps.orientations)
    assert "orientations" in (tmp_path / "out" / "clumps.xdmf").read_text()


def test_history_counts_a_spinning_clump_as_one_rigid_body(tmp_path):
    """A free asymmetric clump (no gravity, no walls) spinning about a skew axis: history.csv's
    rotational_energy is 1/2 omega . I omega of the body (not of its members as spheres) and stays
    constant up to the splitting's O((omega dt)^2) oscillation (1.3e-5 of E at omega dt = 0.02,
    docs/shapes.md; here omega dt ~ 1e-3, so 1e-6 bounds it with a margin of 30); kinetic_energy is
    1/2 M v^2 of the centre of mass."""
    from pdemfem.clumps.quaternion import rotation_matrices
    from pdemfem.plot import read_history

    spheres = [{"position": [0, 0, 0], "radius": RADIUS}, {"position": [1.3 * RADIUS, 0, 0], "radius": 0.8 * RADIUS},
               {"position": [0, 1.1 * RADIUS, 0.4 * RADIUS], "radius": 0.6 * RADIUS}]
    spin = np.array([30.0, -50.0, 80.0])
    group = {"name": "c", "material": "glass", "clump": {"spheres": spheres},
             "insert": {"kind": "list", "positions": [[0, 0, 0]], "velocities": [[0.01, 0.02, 0]],
                        "angular_velocities": [spin.tolist()], "orientations": [[0.9, 0.3, -0.1, 0.3]]}}
    data = scene([group], {"model": "hertz_mindlin", "restitution": 0.5}, gravity=(0, 0, 0), walls=False)
    data["time"] = {"end": 2e-3, "dt": 1e-5}
    data["output"] = {"dir": "out", "every": 2e-4, "particles": []}
    sim = build(data, tmp_path)
    c = sim.clumps
    rotation = rotation_matrices(sim.particle_system.clumps.orientations)[0]
    inertia = rotation @ np.diag(c.principal_inertia[0]) @ rotation.T
    expected = 0.5 * spin @ inertia @ spin
    assert np.linalg.norm(spin) * sim.dt < 1.1e-3
    sim.run(progress=False)
    history = read_history(tmp_path / "out" / "history.csv")
    assert len(history["time"]) > 5
    # Round-off of the L -> omega -> energy products: a few eps.
    assert abs(history["rotational_energy"][0] - expected) <= 1e-13 * expected
    assert np.abs(history["rotational_energy"] - expected).max() <= 1e-6 * expected
    assert np.allclose(history["kinetic_energy"], 0.5 * c.masses[0] * (0.01 ** 2 + 0.02 ** 2), rtol=1e-13, atol=0)
    # The spheres' own formula (2/5 m r^2 per member, spinning about its centre) would differ by far.
    state = sim.particle_system.state
    as_spheres = 0.5 * np.sum(np.einsum("ij,ij->i", state.angular_velocities, state.angular_velocities)
                              / state.inverse_inertia)
    assert abs(as_spheres - expected) > 0.1 * expected


def test_member_index_follows_the_rows_and_stands_while_they_stay(tmp_path):
    """refresh_rows at a rebuild: the member index (each owned row's body, the members' levers) is remade
    when the owned rows hold other particles (here reversed), and kept as it is, without a pass over
    the members, when they hold the same ones."""
    from pdemfem.clumps.bodies import OFFSET_FIELD
    from pdemfem.clumps.quaternion import rotation_matrices

    sim = build(pile(tmp_path, "run"), tmp_path)
    sim.step(50)
    system = sim.particle_system
    clumps, state = system.clumps, system.state

    def check_index():
        body = state.fields[BODY_FIELD][:state.owned_count]
        rotations = rotation_matrices(clumps.orientations)
        assert len(clumps.row_body) == state.owned_count
        assert clumps.member_count == np.count_nonzero(body >= 0)
        assert np.array_equal(clumps.row_body < 0, body < 0)
        for b, identity in enumerate(clumps.ids):
            mine = np.flatnonzero(clumps.row_body == b)
            assert np.array_equal(mine, np.flatnonzero(body == identity))
            levers = clumps.row_levers[mine]
            # R(q) offset from the same numbers; the kernel sums in another order: round-off of a lever
            assert np.abs(levers - state.fields[OFFSET_FIELD][mine] @ rotations[b].T).max() <= 4 * EPS * 3e-3

    check_index()
    kept = clumps.row_body
    clumps.refresh_rows(state)
    assert clumps.row_body is kept  # the same particles in the same rows: nothing redone
    state.reorder(np.arange(state.owned_count)[::-1].copy())
    clumps.refresh_rows(state)
    assert clumps.row_body is not kept
    check_index()


def test_free_spheres_beside_clumps_fall_as_spheres(tmp_path):
    """A scene of clumps and plain spheres: the spheres take both half kicks of the sphere integrator (the
    second half skips them only when every owned row is a clump member).  Free fall far from everything:
    velocity Verlet is exact for a constant force, so after n steps v = g n dt and the drop is g (n dt)^2 / 2,
    to the round-off of n additions (n eps of the scale)."""
    spheres = {"name": "spheres", "material": "glass", "radius": RADIUS,
               "insert": {"kind": "list", "positions": [[0.1, 0.0, 0.5], [0.2, 0.0, 0.5]]}}
    clumps = {"name": "clumps", "material": "glass", "clump": dumbbell(),
              "insert": {"kind": "list", "positions": [[-0.1, 0.0, 0.5]]}}
    simulation = build(scene([clumps, spheres], {"model": "hertz_mindlin", "restitution": 0.5, "friction": 0.5}),
                       tmp_path)
    steps = 200
    simulation.step(steps)
    elapsed = steps * simulation.dt
    particles = simulation.particles
    free = particles.positions[:, 0] > 0.05  # the spheres (the dumbbell sits at x = -0.1)
    assert np.count_nonzero(free) == 2
    tolerance = steps * EPS
    assert np.allclose(particles.velocities[free, 2], -9.81 * elapsed, rtol=tolerance, atol=0.0)
    assert np.allclose(particles.positions[free, 2], 0.5 - 0.5 * 9.81 * elapsed ** 2, rtol=tolerance, atol=0.0)
    # the dumbbell falls alike (its members' velocities come from the body)
    assert np.allclose(particles.velocities[~free, 2], -9.81 * elapsed, rtol=tolerance, atol=0.0)


def test_rotation_constants_follow_the_step_and_the_bodies(tmp_path):
    """The rotation's angle factors are kept from step to step (rotation_constants): a first half with
    another dt, the same again, one after the bodies were re-derived with other moments, and one more
    dt turn the bodies as kick_bodies and drift_bodies do with that dt and those moments, bit for bit."""
    from pdemfem.clumps.rigid_body import drift_bodies, kick_bodies

    sim = build(pile(tmp_path, "run"), tmp_path)
    sim.step(20)
    system = sim.particle_system
    clumps, state = system.clumps, system.state
    # spinning bodies (the pile has not touched yet): the factors decide the turn; |omega| dt ~ 1e-3
    moments = clumps.principal_moments
    clumps.angular_momenta[:] = np.random.default_rng(2).normal(size=(clumps.count, 3)) * moments * 40.0
    for dt, rederive in ((0.5 * system.dt, False), (0.5 * system.dt, False), (0.5 * system.dt, True),
                         (0.25 * system.dt, False)):
        if rederive:  # other moments: the kept factors are stale until the bodies are re-derived, as
            clumps.principal_moments[:] *= 1.5  # after a reorder, a removal or a checkpoint read
            clumps._derive()
        expected = {name: getattr(clumps, name).copy() for name in ("positions", "velocities", "orientations",
                                                                   "angular_momenta")}
        kick_bodies(clumps.count, expected["velocities"], expected["angular_momenta"], clumps.forces, clumps.torques,
                    clumps.inverse_masses, system.gravity, 0.5 * dt)
        drift_bodies(clumps.count, expected["positions"], expected["velocities"], expected["orientations"],
                     expected["angular_momenta"], clumps.principal_moments, dt)
        clumps.first_half(state, system.gravity, dt)
        for name, values in expected.items():
            assert np.array_equal(getattr(clumps, name), values), name


# ------------------------------------------------------------------ the deferred second half

def eager_and_deferred(data, tmp_path):
    """Two simulations of `data`: one doing the clumps' second half within each step (as the particle system
    does by itself), one leaving it to the next step's first half (the Simulation's choice without solids)."""
    eager, deferred = build(data, tmp_path, "eager"), build(data, tmp_path, "deferred")
    assert deferred.particle_system.clumps.defer_second_half
    eager.particle_system.clumps.defer_second_half = False
    return eager, deferred


def assert_same_state(a, b):
    for name in ("ids", "positions", "velocities", "angular_velocities", "forces"):
        assert np.array_equal(getattr(a.particles, name), getattr(b.particles, name)), name
    for name in ("ids", "positions", "orientations", "velocities", "angular_velocities"):
        assert np.array_equal(getattr(a.clumps, name), getattr(b.clumps, name)), name
    assert a.energies() == b.energies()


def checkpoint_arrays(path):
    arrays = {}
    with h5py.File(path, "r") as handle:
        handle.visititems(lambda name, item: arrays.__setitem__(name, item[()])
                          if isinstance(item, h5py.Dataset) else None)
    return arrays


def test_deferred_second_half_leaves_every_reader_between_steps_the_eager_state(tmp_path):
    """Within Simulation.step(n) the clumps' second half (bodies' kick, omega, members' velocities and spins)
    waits for the next step's first half, which does the kick in its own pass (ClumpBodies.defer_second_half).
    After every call, whatever its step count, the member rows (sim.particles), the bodies (sim.clumps) and
    the energies are bit for bit those of a run doing the second half within each step; so are run's history
    rows and checkpoints.  Ten clumps thrown onto a floor, touching it and each other from step ~300."""
    data = pile(tmp_path, "run")
    dt = build(data, tmp_path, "probe").dt
    data["time"]["end"] = 600 * dt
    data["checkpoint"] = {"every": 200 * dt, "keep": 5}
    data["output"]["every"] = 100 * dt
    eager, deferred = eager_and_deferred(data, tmp_path)
    for count in (1, 2, 37, 160):  # to step 200
        eager.step(count)
        deferred.step(count)
        assert_same_state(eager, deferred)
    eager.run(progress=False)
    deferred.run(progress=False)
    assert deferred.step_count == 600 and deferred.contact_count() > 0
    assert_same_state(eager, deferred)
    assert (tmp_path / "eager" / "history.csv").read_text() == (tmp_path / "deferred" / "history.csv").read_text()
    for step in (400, 600):
        name = f"checkpoints/checkpoint_{step:012d}.h5"
        a, b = checkpoint_arrays(tmp_path / "eager" / name), checkpoint_arrays(tmp_path / "deferred" / name)
        assert a.keys() == b.keys() and any("clump" in key for key in a)
        for key in a:
            assert np.array_equal(a[key], b[key]), key


def test_a_stream_inserting_beside_clumps_finds_their_second_half_done(tmp_path):
    """A stream of spheres beside clumps inserts at the start of steps inside one Simulation.step(n) call;
    its list rebuild (which migrates and re-indexes the members' rows, and refuses a pending kick) comes
    after the clumps' pending second half is done: the run stays bit for bit the eager one."""
    data = pile(tmp_path, "run")
    dt = build(data, tmp_path, "probe").dt
    data["particles"].append({"name": "feed", "material": "glass", "radius": 0.5 * RADIUS,
                              "insert": {"kind": "stream", "rate": 2.0 / (40 * dt), "interval": 40 * dt,
                                         "velocity": [0.0, 0.0, -1.0], "seed": 5,
                                         "region": {"box": [[-4e-3, -4e-3, 1.0e-2], [4e-3, 4e-3, 1.2e-2]]}}})
    eager, deferred = eager_and_deferred(data, tmp_path)
    eager.step(300)
    deferred.step(300)
    assert deferred.streams.inserted >= 10
    assert_same_state(eager, deferred)


def test_readers_of_the_state_refuse_a_pending_second_half(tmp_path):
    """The particle system's own step leaves the deferred second half pending: the energies, a checkpoint
    and a list rebuild refuse to read the state until finish_clump_step has done it."""
    sim = build(pile(tmp_path, "run"), tmp_path)
    system = sim.particle_system
    system.step()
    for reader in (system.energies, system.clumps.state_dict, system._rebuild):
        with pytest.raises(RuntimeError, match="pending"):
            reader()
    system.finish_clump_step()
    system.energies()
    system._rebuild()

"""Verification of the neighbour list (pdemfem/neighbors/verlet.py) inside the DEM step.

1. After many steps with rebuilds (skin/2 displacement rule), the contacts the Verlet
   list sees equal the brute-force O(n^2) contact set: no contact is ever missed.
2. Tangential history survives a rebuild: a sliding contact carries the same
   tangential force across a forced rebuild (and re-sort) as without it.
"""
from __future__ import annotations

import numpy as np
import pytest

from mpi_cases.dem_scenes import GLASS, dense_scene, two_spheres
from pdemfem import Simulation
from pdemfem.neighbors.cells import cell_grid


def _list_pairs(neighbors):
    """(first, second) particle indices of every listed pair, for either list layout."""
    if hasattr(neighbors, "pair_rows"):
        return neighbors.pair_rows()
    offsets = neighbors.offsets
    return np.repeat(np.arange(len(offsets) - 1), np.diff(offsets)), neighbors.partners


def _contact_sets(sim):
    state = sim.particle_system.state
    x, r, ids = state.positions, state.radii, state.ids
    count = len(ids)
    # Brute force: every pair.
    i, j = np.triu_indices(count, k=1)
    overlap = r[i] + r[j] - np.linalg.norm(x[i] - x[j], axis=1)
    brute = {(min(a, b), max(a, b)) for a, b in zip(ids[i[overlap > 0]], ids[j[overlap > 0]])}
    # The list's view.
    first, second = _list_pairs(sim.particle_system.neighbors)
    overlap = r[first] + r[second] - np.linalg.norm(x[first] - x[second], axis=1)
    listed = {(min(a, b), max(a, b)) for a, b in zip(ids[first[overlap > 0]], ids[second[overlap > 0]])}
    return brute, listed


def _wall_contacts(sim):
    state, walls = sim.particle_system.state, sim.particle_system.walls
    distance = (state.positions[:, None, :] - walls.points[None, :, :]) @ np.eye(3)
    distance = np.einsum("pwk,wk->pw", state.positions[:, None, :] - walls.points[None, :, :], walls.normals)
    return int(np.count_nonzero(state.radii[:, None] - distance > 0.0))


def test_verlet_contacts_equal_brute_force():
    sim = Simulation.from_dict(dense_scene(count=200))
    builds_at_start = sim.particle_system.neighbors.builds
    checked_contacts = 0
    for _ in range(12):
        sim.step(400)
        brute, listed = _contact_sets(sim)
        # Exact set equality: a pair missing from the list would be a missed contact.
        assert listed == brute
        # And the force loop counts exactly these contacts plus the wall contacts.
        assert sim.contact_count() == len(brute) + _wall_contacts(sim)
        checked_contacts += len(brute)
    # The run must have rebuilt the list many times and have had contacts to check.
    assert sim.particle_system.neighbors.builds - builds_at_start >= 20
    assert checked_contacts > 500


def _listed_pairs(positions, radii, skin, owned):
    """The list build's kernel on its own: (order, offsets, partners, pair count) of particles whose first
    `owned` are owned and the rest ghosts."""
    from pdemfem.neighbors.cells import cell_grid, cell_indices, sort_by_cell
    from pdemfem.neighbors.verlet import _FORWARD_ROWS, _fill_pairs

    count = len(positions)
    lower, size, dimensions = cell_grid(positions, 2.0 * radii.max() + skin)
    cells = cell_indices(positions, lower, size, dimensions)
    order, starts = sort_by_cell(cells, int(np.prod(dimensions)))
    offsets = np.empty(count + 1, dtype=np.int64)
    partners = np.empty(100 * count, dtype=np.int32)
    written = _fill_pairs(np.ascontiguousarray(positions[order]), radii[order], skin, owned, order, cells[order],
                          starts, dimensions, _FORWARD_ROWS, np.zeros(count, np.int32), np.zeros((1, 1)), False,
                          np.zeros(0, np.int64), offsets, partners)
    return order, offsets, partners, written

@pytest.mark.parametrize("seed", range(4))
def test_list_build_holds_every_pair_within_the_cutoff_once(seed):
    """The stencil's runs of cells (pdemfem/neighbors/verlet.py) against all pairs: every pair closer than
    r_i + r_j + skin with at least one owned particle is listed exactly once, on grids of a few cells a side
    (most particles sit in boundary cells) and with ghosts."""
    rng = np.random.default_rng(seed)
    count = 1500
    positions = rng.random((count, 3)) * rng.uniform(0.002, 0.02, 3)
    radii = rng.uniform(0.5e-3, 1.0e-3, count)
    skin, owned = 0.3e-3, 1000
    order, offsets, partners, written = _listed_pairs(positions, radii, skin, owned)
    listed = sorted((min(a, b), max(a, b)) for a, b in zip(np.repeat(order, np.diff(offsets)), partners[:written]))
    i, j = np.triu_indices(count, k=1)
    near = np.linalg.norm(positions[i] - positions[j], axis=1) < radii[i] + radii[j] + skin
    near &= (i < owned) | (j < owned)
    assert listed == sorted(zip(i[near].tolist(), j[near].tolist()))  # sorted lists: a pair listed twice fails


def test_split_puts_each_rows_pairs_of_owned_particles_first():
    """VerletList's split at the ghosts (the interior pass runs while the ghosts' update travels): each row
    keeps its partners, the owned ones first and in their order, then the ghosts in theirs; interior_ends
    marks the border; a ghost's row is all boundary."""
    from pdemfem.neighbors.verlet import _owned_partners_first

    rng = np.random.default_rng(7)
    count, owned = 1500, 1000
    positions = rng.random((count, 3)) * 0.012
    radii = rng.uniform(0.5e-3, 1.0e-3, count)
    order, offsets, partners, written = _listed_pairs(positions, radii, 0.3e-3, owned)
    before = partners[:written].copy()
    interior_ends = np.empty(count, dtype=np.int64)
    boundary_rows = _owned_partners_first(order, offsets, partners[:written], owned, interior_ends, 0)
    with_ghost_rows = 0
    for p in range(count):
        row, split = partners[offsets[p]:offsets[p + 1]], interior_ends[p] - offsets[p]
        original = before[offsets[p]:offsets[p + 1]]
        if order[p] >= owned:
            assert split == 0
        else:
            assert row[:split].tolist() == [j for j in original if j < owned]
            assert row[split:].tolist() == [j for j in original if j >= owned]
        with_ghost_rows += split < len(row)
    assert boundary_rows == with_ghost_rows > 0
    assert np.count_nonzero(before >= owned) > 0  # owned rows with ghost partners were there to move

def test_late_rows_come_last_with_the_same_pairs():
    """VerletList.build with late_rows (ghosts and the owned particles sent as ghosts): the same pairs, each
    row's the same partners, the late particles' rows after all others (each part in cell order), and every
    row with a pair with a ghost among them, so that the pass over those pairs reads one block of the list."""
    from types import SimpleNamespace

    from pdemfem.neighbors.history import RECORD_KEYS
    from pdemfem.neighbors.verlet import VerletList

    rng = np.random.default_rng(11)
    count, owned = 1500, 1000
    positions = rng.random((count, 3)) * 0.012
    state = SimpleNamespace(count=count, owned_count=owned, positions=positions, ids=np.arange(count),
                            radii=rng.uniform(0.5e-3, 1.0e-3, count), material_index=np.zeros(count, np.int32),
                            fields={})
    no_records = np.zeros((0, RECORD_KEYS + 3))
    plain, late_list = VerletList(), VerletList()
    plain.build(state, 0.3e-3, no_records)
    # Late: the ghosts, the owned particles with a ghost partner (what sending them as ghosts guarantees) and
    # some others (a particle sent as a ghost may have no pair across the cut).
    late = np.zeros(count, dtype=bool)
    late[owned:] = True
    first, second = plain.pair_rows()
    late[np.where(second >= owned, first, second)[(first >= owned) | (second >= owned)]] = True
    late[rng.choice(owned, 100, replace=False)] = True
    assert 0 < np.count_nonzero(late[:owned]) < owned
    late_list.build(state, 0.3e-3, no_records, late)

    def rows(verlet):
        return {int(i): sorted(verlet.partners[verlet.offsets[r]:verlet.offsets[r + 1]].tolist())
                for r, i in enumerate(verlet.row_particles)}
    assert rows(late_list) == rows(plain)
    row_is_late = late[late_list.row_particles]
    first_late = int(np.argmax(row_is_late))
    assert not row_is_late[:first_late].any() and row_is_late[first_late:].all()
    # Each part keeps the cell order of the plain build (its rows in the same relative order).
    plain_rank = np.empty(count, dtype=np.int64)
    plain_rank[plain.row_particles] = np.arange(count)
    assert np.all(np.diff(plain_rank[late_list.row_particles[:first_late]]) > 0)
    assert np.all(np.diff(plain_rank[late_list.row_particles[first_late:]]) > 0)
    boundary_rows = late_list.boundary[0]
    assert len(boundary_rows) > 0 and late[boundary_rows].all()

    # The split read only the late rows, and found the same pairs with a ghost as the plain build's over all rows.
    def pairs_with_a_ghost(verlet):
        rows, starts, ends = verlet.boundary
        return sorted((int(i), int(j)) for i, start, end in zip(rows, starts, ends)
                      for j in verlet.partners[start:end])
    assert pairs_with_a_ghost(late_list) == pairs_with_a_ghost(plain)
    assert late_list.interior_pair_count == plain.interior_pair_count > 0
    assert all(j >= owned or i >= owned for i, j in pairs_with_a_ghost(late_list))


def _sliding_pair(tangential_speed):
    """Two spheres in an oblique contact (relative normal speed 0.1 m/s, mu = 0.3) with spectators
    around them, so that a rebuild re-sorts the particles (cell order != id order).

    tangential_speed 0.8 m/s: gross sliding (the force sits on the Coulomb cap);
    0.01 m/s: sticking, where the force is the spring S_t xi and depends on the history.
    """
    r = 1.0e-3
    spectators = [((x, y, 0.0), r) for x, y in ((6e-3, 0.0), (-6e-3, 0.0), (0.0, 6e-3), (0.0, -6e-3))]
    scene = two_spheres(radii=(r, r), materials=(GLASS, GLASS),
                        positions=[(0.0, 0.0, 2.01 * r), (0.0, 0.0, 0.0)],
                        velocities=[(0.5 * tangential_speed, 0.0, -0.05), (-0.5 * tangential_speed, 0.0, 0.05)], dt=2.0e-6, restitution=0.5,
                        friction=0.3, expected_impact_speed=0.1, extra_particles=spectators)
    return Simulation.from_dict(scene)


def _by_id(sim, field):
    p = sim.particles
    return getattr(p, field)[np.argsort(p.ids)]


@pytest.mark.parametrize("tangential_speed", [0.8, 0.01])
def test_history_survives_rebuild(tangential_speed):
    reference, rebuilt, forgotten = (_sliding_pair(tangential_speed) for _ in range(3))
    # Step into the middle of the contact (contact starts after ~10 steps, lasts ~150).
    for sim in (reference, rebuilt, forgotten):
        while sim.contact_count() == 0:
            sim.step(1)
        sim.step(40)
    assert np.abs(rebuilt.particle_system.neighbors.history).max() > 0.0
    rebuilt.particle_system._rebuild()
    forgotten.particle_system.neighbors.history[:] = 0.0
    force_scale = np.abs(_by_id(reference, "forces")[:2]).max()
    velocity_scale = np.abs(_by_id(reference, "velocities")[:2]).max()
    round_off = 4 * np.finfo(float).eps
    for _ in range(20):
        for sim in (reference, rebuilt, forgotten):
            sim.step(1)
        # Same tangential (and normal) force after the rebuild.  Each sphere has this one contact, so there
        # is no sum to reorder; the re-sort may swap the pair's roles (i, j), which negates every difference
        # exactly.  Allowed: a few eps (measured identical).
        assert np.allclose(_by_id(rebuilt, "forces"), _by_id(reference, "forces"), rtol=0,
                           atol=round_off * force_scale)
        assert np.allclose(_by_id(rebuilt, "velocities"), _by_id(reference, "velocities"), rtol=0,
                           atol=round_off * velocity_scale)
    # Control: while sticking, dropping the history changes the force by far more (so the
    # comparison above can fail).  While sliding the force is mu F_n whatever the spring
    # held, so there the history shows only once the contact sticks again.
    if tangential_speed < 0.1:
        difference = np.abs(_by_id(forgotten, "forces") - _by_id(reference, "forces")).max()
        assert difference > 1e-2 * force_scale


def _spheres_on_walls():
    """A sphere rocking on the floor (sticking: the tangential force is the spring, so it depends on the
    history) and one in the floor-wall edge sliding along it slowly (two wall contacts), with spectators in
    between so that a rebuild re-sorts the rows; gravity, tilted towards the side wall (tan = 0.2, below the
    friction 0.3), keeps them pressed on."""
    r = 1.0e-3
    spectators = [((x, 6e-3, 0.5e-3 + r), r) for x in (2e-3, 6e-3, 10e-3)]
    scene = two_spheres(radii=(r, r), materials=(GLASS, GLASS),
                        # Hertz's resting overlaps under this gravity: 0.56 um on the floor, 0.2 um on the side.
                        positions=[(8e-3, 3e-3, r - 5.6e-7), (r - 2e-7, 10e-3, r - 5.6e-7)],
                        velocities=[(0.01, 0.004, 0.0), (0.0, 0.005, 0.0)], dt=2.0e-6, restitution=0.5,
                        friction=0.3, expected_impact_speed=0.1, extra_particles=spectators,
                        gravity=(-2.0, 0.0, -9.81))
    scene["walls"] = [
        {"name": "floor", "kind": "plane", "point": [0, 0, 0], "normal": [0, 0, 1], "material": "a"},
        {"name": "side", "kind": "plane", "point": [0, 0, 0], "normal": [1, 0, 0], "material": "a"},
    ]
    return Simulation.from_dict(scene)


def test_plane_wall_history_survives_rebuild():
    """The plane walls' springs live on the list build's candidates; a forced rebuild (new candidates) must
    hand every spring to the same (particle, wall) contact (test_wall_records_follow_their_particles: rows
    that change)."""
    reference, rebuilt, forgotten = (_spheres_on_walls() for _ in range(3))
    for sim in (reference, rebuilt, forgotten):
        sim.step(400)
    walls = rebuilt.particle_system.walls
    held = walls.candidate_walls[np.any(walls.candidate_history != 0.0, axis=1)]
    assert sorted(held.tolist()) == [0, 0, 1]  # two floor springs and the side wall's
    rebuilt.particle_system._rebuild()
    forgotten.particle_system.walls.candidate_history[:] = 0.0
    force_scale = np.abs(_by_id(reference, "forces")[:2]).max()
    for _ in range(20):
        for sim in (reference, rebuilt, forgotten):
            sim.step(1)
        # Each sphere sums its wall contacts in wall order whatever its row: the same bits (exact).
        assert np.array_equal(_by_id(rebuilt, "forces"), _by_id(reference, "forces"))
        assert np.array_equal(_by_id(rebuilt, "velocities"), _by_id(reference, "velocities"))
    # Control: dropping the springs changes the force by far more (so the comparison above can fail).
    difference = np.abs(_by_id(forgotten, "forces") - _by_id(reference, "forces"))[:2].max()
    assert difference > 1e-2 * force_scale


def test_wall_records_follow_their_particles():
    """Records taken from one set of candidates restore each (particle id, wall) spring onto the candidates
    built after the rows were permuted and some particles left; a record of a particle not owned here, or of a
    contact no longer a candidate, is dropped."""
    from pdemfem.neighbors.history import RECORD_KEYS, collect_wall_records_into, restore_wall_records
    from pdemfem.walls.plane import _near_walls

    rng = np.random.default_rng(5)
    count, width = 300, 4
    positions = rng.random((count, 3))
    radii = np.full(count, 0.05)
    ids = rng.permutation(10 * count)[:count].astype(np.int64)  # sparse ids: the binary-search look-up
    points = np.array([[0.0, 0.0, 0.0], [0.0, 0.0, 0.0], [1.0, 1.0, 1.0]])
    normals = np.array([[0.0, 0.0, 1.0], [1.0, 0.0, 0.0], [0.0, -1.0, 0.0]])
    particles, walls = _near_walls(positions, radii, 0.05, points, normals)
    history = rng.standard_normal((len(particles), width))
    history[::7] = 0.0  # springs not in use: no record
    records = np.empty((len(particles), RECORD_KEYS + width))
    written = collect_wall_records_into(particles, walls, history, ids, records, 0)
    assert written == len(particles) - len(particles[::7])
    spring = {(ids[i], w): history[c] for c, (i, w) in enumerate(zip(particles, walls)) if np.any(history[c])}
    # Permute the rows, keep 250 of them, and move every particle a little (some candidates change).
    rows = rng.permutation(count)[:250]
    new_positions = positions[rows] + 0.02 * rng.standard_normal((250, 3))
    new_particles, new_walls = _near_walls(new_positions, radii[rows], 0.05, points, normals)
    new_history = np.zeros((len(new_particles), width))
    restore_wall_records(new_particles, new_walls, new_history, ids[rows], 250, records[:written])
    restored = 0
    for c, (i, w) in enumerate(zip(new_particles, new_walls)):
        expected = spring.get((ids[rows][i], w), np.zeros(width))
        assert np.array_equal(new_history[c], expected)
        restored += np.any(expected != 0.0)
    assert 0 < restored < len(spring)  # some springs moved with their particle, some were dropped


def test_cell_grid_of_a_spread_out_scene_counts_its_cells_without_overflow_and_stops_a_diverged_one():
    """Two particles 1e9 cells apart along each axis: 1e27 cells overflowed int64 to a negative count, the grid
    was accepted, and the sort failed with "negative dimensions not allowed".  Past 1e10 cells (positions
    beyond the range the scene may start in) the run diverged: a SolverError names it."""
    from pdemfem.errors import SolverError

    spread = np.array([[0.0, 0.0, 0.0], [1.0e9, 1.0e9, 1.0e9]])
    lower, size, dimensions = cell_grid(spread, 1.0)
    assert np.all(dimensions >= 1) and np.prod(dimensions.astype(float)) <= 64
    assert np.all(lower + size * dimensions >= spread.max(axis=0))
    with pytest.raises(SolverError, match="the simulation diverged"):
        cell_grid(np.array([[0.0, 0.0, 0.0], [0.0, 0.0, 2.0e10]]), 1.0)
    empty_lower, _, empty_dimensions = cell_grid(np.zeros((0, 3)), 1.0)
    assert np.all(empty_dimensions == 1)

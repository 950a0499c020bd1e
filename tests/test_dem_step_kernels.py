"""The DEM step's helper kernels against the plain numpy (or previous) computations they replace.

Each must give exactly the same result (they only change how it is computed): the cell sort and cell
starts, the out-of-domain mask, the fused first half kick + drift, and the contact-history restore
(records grouped by owner instead of a hash table), including duplicate records (the first wins),
pairs seen from a ghost (the springs flip) and ids too sparse for an id-indexed table.
"""
from __future__ import annotations

import numpy as np
import pytest

from pdemfem.neighbors.cells import cell_starts, out_of_order_runs, sort_by_cell
from pdemfem.neighbors.history import collect_records, restore_records
from pdemfem.particles.integrate import drift, kick, kick_drift, outside_domain


@pytest.mark.parametrize("count, cells", [(0, 4), (1, 1), (500, 40), (3000, 20000)])
def test_sort_by_cell_is_a_stable_argsort(count, cells):
    rng = np.random.default_rng(count)
    indices = rng.integers(0, cells, count).astype(np.int64)
    order, starts = sort_by_cell(indices, cells)
    assert np.array_equal(order, np.argsort(indices, kind="stable"))
    expected_starts = np.searchsorted(indices[order], np.arange(cells + 1))
    assert np.array_equal(starts, expected_starts)
    assert np.array_equal(cell_starts(indices[order], cells), expected_starts)


def test_out_of_order_runs_counts_breaks():
    assert out_of_order_runs(np.arange(6)) == 0
    # One particle moved three rows down: three breaks, not the four rows whose index changed.
    assert out_of_order_runs(np.array([0, 2, 3, 4, 1, 5])) == 3


def test_outside_domain_matches_numpy():
    rng = np.random.default_rng(3)
    positions = rng.uniform(-6.0, 6.0, (400, 3))
    positions[7, 1] = np.nan
    positions[9] = [np.inf, 100.0, -np.inf]  # not finite and out of bounds: removed and counted once
    lower = np.array([-5.0, -np.inf, -5.0])
    upper = np.array([5.0, np.inf, 4.0])
    bounded = np.array([True, False, True])
    owned = 390
    mask, nonfinite = outside_domain(owned, positions, lower, upper, bounded)
    owned_positions = positions[:owned]
    finite = np.all(np.isfinite(owned_positions), axis=1)
    with np.errstate(invalid="ignore"):
        expected = ~finite | np.any(((owned_positions < lower) | (owned_positions > upper)) & bounded, axis=1)
    assert np.array_equal(mask, expected)
    assert nonfinite == np.count_nonzero(~finite) == 2


def test_kick_drift_equals_kick_then_drift():
    rng = np.random.default_rng(5)
    count, owned = 50, 45
    arrays = {name: rng.normal(size=(count, 3)) for name in
              ("positions", "velocities", "angular_velocities", "forces", "torques", "positions_at_build")}
    inverse_mass = rng.uniform(1.0, 3.0, count)
    inverse_inertia = rng.uniform(1.0, 3.0, count)
    gravity = np.array([0.0, 0.0, -9.81])
    dt = 1e-3
    separate = {name: values.copy() for name, values in arrays.items()}
    kick(owned, separate["velocities"], separate["angular_velocities"], separate["forces"], separate["torques"],
         inverse_mass, inverse_inertia, gravity, 0.5 * dt)
    largest = drift(owned, separate["positions"], separate["velocities"], dt, separate["positions_at_build"])
    fused = {name: values.copy() for name, values in arrays.items()}
    fused_largest = kick_drift(owned, fused["positions"], fused["velocities"], fused["angular_velocities"],
                               fused["forces"], fused["torques"], inverse_mass, inverse_inertia, gravity, 0.5 * dt,
                               dt, fused["positions_at_build"])
    # Bit-identical: the same operations in the same order.
    assert fused_largest == largest
    for name in ("positions", "velocities", "angular_velocities"):
        assert np.array_equal(fused[name], separate[name]), name
    # The loads of the owned rows are used up (zeroed for the next evaluation); the ghost rows' are untouched.
    for name in ("forces", "torques"):
        assert not np.any(fused[name][:owned])
        assert np.array_equal(fused[name][owned:], arrays[name][owned:])


def test_kick_equals_the_numpy_expression():
    """kick walks flat rows with the components written out; it must give numpy's bits for
    v += dt/2 (F/m + g), w += dt/2 T/I, and leave the rows past owned_count alone."""
    rng = np.random.default_rng(11)
    count, owned = 37, 33
    velocities, angular_velocities, forces, torques = (rng.normal(size=(count, 3)) for _ in range(4))
    inverse_mass = rng.uniform(1.0, 3.0, count)
    inverse_inertia = rng.uniform(1.0, 3.0, count)
    gravity = np.array([0.5, -1.0, -9.81])
    half_dt = 0.37e-3
    expected_velocities = velocities.copy()
    expected_spins = angular_velocities.copy()
    expected_velocities[:owned] += half_dt * (forces[:owned] * inverse_mass[:owned, None] + gravity)
    expected_spins[:owned] += half_dt * torques[:owned] * inverse_inertia[:owned, None]
    kick(owned, velocities, angular_velocities, forces, torques, inverse_mass, inverse_inertia, gravity, half_dt)
    assert np.array_equal(velocities, expected_velocities)
    assert np.array_equal(angular_velocities, expected_spins)


@pytest.mark.parametrize("bad", [np.nan, np.inf])
def test_kick_drift_reports_a_non_finite_displacement(bad):
    """A blown-up particle anywhere in the rows makes the largest displacement inf (the caller rebuilds at
    once and removes it), also when a larger finite displacement comes after it."""
    count = 9
    positions = np.zeros((count, 3))
    velocities = np.zeros((count, 3))
    velocities[8, 0] = 1e3  # the largest finite displacement, after the bad row
    positions[2, 1] = bad
    zeros = np.zeros((count, 3))
    largest = kick_drift(count, positions, velocities, zeros.copy(), zeros.copy(), zeros.copy(), np.ones(count),
                         np.ones(count), np.zeros(3), 0.5e-3, 1e-3, np.zeros((count, 3)))
    assert largest == np.inf
    positions = np.zeros((count, 3))  # no bad row: the largest finite displacement, (dt v)^2
    largest = kick_drift(count, positions, velocities, zeros.copy(), zeros.copy(), zeros.copy(), np.ones(count),
                         np.ones(count), np.zeros(3), 0.5e-3, 1e-3, np.zeros((count, 3)))
    assert largest == (1e-3 * 1e3) ** 2


def _hash_restore(row_particles, offsets, partners, history, ids, owned_count, records, signs):
    """The reference: for every listed pair, the first record with (owned i, j), else the first with (owned j, i)
    (springs flipped)."""
    first_record = {}
    for k in range(len(records)):
        first_record.setdefault((int(records[k, 0]), int(records[k, 1])), k)
    for r, i in enumerate(row_particles):
        for row in range(offsets[r], offsets[r + 1]):
            j = partners[row]
            k = first_record.get((int(ids[i]), int(ids[j]))) if i < owned_count else None
            flipped = k is None
            if flipped and j < owned_count:
                k = first_record.get((int(ids[j]), int(ids[i])))
            if k is not None:
                values = records[k, 2:]
                history[row] = signs * values if flipped else values


def _random_list(rng, count, owned_count):
    """A half list over `count` rows (the first `owned_count` owned) without ghost-ghost pairs."""
    row_particles = rng.permutation(count)
    offsets = [0]
    partners = []
    for r, i in enumerate(row_particles):
        later = row_particles[r + 1:]
        if i >= owned_count:
            later = later[later < owned_count]
        chosen = rng.choice(later, size=min(len(later), int(rng.integers(0, 5))), replace=False)
        partners.extend(chosen)
        offsets.append(len(partners))
    return row_particles.astype(np.int64), np.array(offsets, dtype=np.int64), np.array(partners, dtype=np.int32)


@pytest.mark.parametrize("id_stride", [1, 1000])  # dense ids (an id-indexed table) and sparse (binary search)
def test_restore_records_matches_a_lookup_by_pair(id_stride):
    rng = np.random.default_rng(id_stride)
    count, owned_count, width = 300, 240, 4
    signs = np.array([-1.0, -1.0, -1.0, 1.0])
    ids = (rng.permutation(count) * id_stride + 17).astype(np.int64)
    row_particles, offsets, partners = _random_list(rng, count, owned_count)
    history = rng.normal(size=(len(partners), width))
    history[rng.random(len(partners)) < 0.4] = 0.0  # pairs apart: no record
    records = collect_records(row_particles, offsets, partners, history, ids, owned_count, signs)
    assert len(records) > 100
    # Shuffled, some lost, some duplicated with other values after the originals (the originals win),
    # and records of a particle not held here.
    records = records[rng.permutation(len(records))][10:]
    duplicates = records[:20].copy()
    duplicates[:, 2:] += 1.0
    stranger = np.array([[10 ** 9, ids[0], 1.0, 2.0, 3.0, 4.0]])
    records = np.ascontiguousarray(np.concatenate([records, duplicates, stranger]))
    # The new list: the same pairs, each seen from either particle, rows in another order.
    first = np.repeat(row_particles, np.diff(offsets))
    swap = rng.random(len(partners)) < 0.5
    rows_of = {}
    for a, b, flip in zip(first, partners, swap):
        a, b = (int(b), int(a)) if flip else (int(a), int(b))
        rows_of.setdefault(a, []).append(b)
    row_particles = rng.permutation(count).astype(np.int64)
    partners = np.array([b for a in row_particles for b in rows_of.get(int(a), [])], dtype=np.int32)
    offsets = np.concatenate([[0], np.cumsum([len(rows_of.get(int(a), [])) for a in row_particles])]).astype(np.int64)
    expected = np.zeros((len(partners), width))
    _hash_restore(row_particles, offsets, partners, expected, ids, owned_count, records, signs)
    restored = np.zeros((len(partners), width))
    restore_records(row_particles, offsets, partners, restored, ids, owned_count, records, signs)
    assert np.count_nonzero(np.any(expected != 0.0, axis=1)) > 20
    assert np.array_equal(restored, expected)


def test_one_record_per_pair_restores_what_one_per_particle_restores():
    """Collected one per pair (one rank, nothing migrates), the records restore every pair's history, seen from
    either particle in the new list, exactly as the records of both particles do; and there are as many as
    pairs with history, against one per owned particle of each."""
    rng = np.random.default_rng(5)
    count, owned_count, width = 300, 240, 4
    signs = np.array([-1.0, -1.0, -1.0, 1.0])
    ids = (rng.permutation(count) + 3).astype(np.int64)
    row_particles, offsets, partners = _random_list(rng, count, owned_count)
    history = rng.normal(size=(len(partners), width))
    history[rng.random(len(partners)) < 0.4] = 0.0
    both = collect_records(row_particles, offsets, partners, history, ids, owned_count, signs)
    single = collect_records(row_particles, offsets, partners, history, ids, owned_count, signs, True)
    in_use = np.any(history != 0.0, axis=1)
    assert len(single) == np.count_nonzero(in_use)
    first = np.repeat(row_particles, np.diff(offsets))
    both_owned = (first < owned_count) & (partners < owned_count)
    assert len(both) == len(single) + np.count_nonzero(in_use & both_owned)
    # The new list: every pair seen from the other particle where both are owned, rows in another order.
    rows_of = {}
    for a, b in zip(first, partners):
        a, b = (int(b), int(a)) if a < owned_count and b < owned_count else (int(a), int(b))
        rows_of.setdefault(a, []).append(b)
    new_rows = rng.permutation(count).astype(np.int64)
    new_partners = np.array([b for a in new_rows for b in rows_of.get(int(a), [])], dtype=np.int32)
    new_offsets = np.concatenate([[0], np.cumsum([len(rows_of.get(int(a), [])) for a in new_rows])]).astype(np.int64)
    from_both = np.zeros((len(new_partners), width))
    from_single = np.zeros((len(new_partners), width))
    restore_records(new_rows, new_offsets, new_partners, from_both, ids, owned_count, both, signs)
    restore_records(new_rows, new_offsets, new_partners, from_single, ids, owned_count, single, signs)
    assert np.count_nonzero(np.any(from_single != 0.0, axis=1)) == np.count_nonzero(in_use)
    assert np.array_equal(from_single, from_both)


def test_contact_kernels_report_the_deepest_overlap_over_the_smaller_radius():
    """Two spheres (r = 1 and 0.5 mm) overlapping by 0.1 mm report 0.1 / 0.5 = 0.2; a 1 mm sphere 0.05 mm into
    a plane reports 0.05 (exact up to round-off of the distance: 1e-12)."""
    from pdemfem.contact.forces import pair_forces, plane_wall_forces
    from pdemfem.contact.layout import COLUMNS, TANGENTIAL

    positions = np.array([[0.0, 0.0, 0.00095], [0.0, 0.0, 0.00235]])  # gap 1.4 mm of a 1.5 mm radius sum
    radii = np.array([0.001, 0.0005])
    zeros = np.zeros((2, 3))
    mass = np.array([1e-5, 1.25e-6])
    coefficients = np.zeros((2, 2, COLUMNS))
    coefficients[:, :, 0] = 1e7  # E*
    coefficients[:, :, 1] = 4e6  # G*
    history = np.zeros((1, 4))
    *_, deepest = pair_forces(np.array([0]), np.array([0]), np.array([1]), np.array([1], dtype=np.int32), history,
                              np.arange(2), 2, positions, zeros.copy(), zeros.copy(), radii, mass, np.ones(2),
                              np.zeros(2, dtype=np.int32), coefficients, TANGENTIAL, 1e-7, zeros.copy(),
                              zeros.copy(), np.zeros(0), np.zeros((0, 2)))
    assert deepest == pytest.approx(0.2, abs=1e-12)
    *_, deepest = plane_wall_forces(np.array([0]), np.array([0]), np.zeros((1, 3)), np.array([[0.0, 0.0, 1.0]]),
                                    np.zeros((1, 3)), np.array([1]), np.zeros((1, 4)), positions, zeros.copy(),
                                    zeros.copy(), radii, mass, np.ones(2), np.zeros(2, dtype=np.int32),
                                    coefficients, TANGENTIAL, 1e-7, zeros.copy(), zeros.copy(), np.zeros((1, 3)),
                                    np.zeros(0), np.zeros((0, 2)), np.zeros(1), np.zeros(1))
    assert deepest == pytest.approx(0.05, abs=1e-12)

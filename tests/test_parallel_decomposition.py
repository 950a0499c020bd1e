"""Spatial decomposition of the DEM on 1-4 ranks (docs/parallel.md).

All scenes are in tests/mpi_cases/parallel_cases.py; one mpiexec launch per rank count runs
every scenario (module fixture), so the whole file costs four interpreter start-ups.  3 and 4
ranks are oversubscribed on a 2-core machine.

Tolerances.  A rank count changes only the order in which floating-point sums are formed
(each rank sums a particle's contact forces in its own list order; energies and wall forces
are per-rank partial sums combined by Allreduce).  Reordering a sum of k terms changes it by
at most ~k eps |sum|; for a particle that is far below one unit in the last place (ulp) of its
position after the step (dt^2 |a| eps << ulp(x)), so a rank count injects at most one
position-ulp per particle per step.  How much one such seed grows over the run is measured:
the serial run is repeated with particle 0 displaced by one ulp ("_ulp" scenarios), and the
largest change it causes, G (per ulp of the perturbed coordinate), bounds the growth of every
seed.  Union bound over N particles x STEPS steps:
    position tolerance = G * ulp(L) * N * STEPS          (L: the largest coordinate)
    quantity tolerance = growth of the quantity under one ulp * N * STEPS + summation floor
with the summation floor eps * N * STEPS * max|quantity| for per-step sums reduced over ranks
(and accumulated, for the dissipated energy).  Each assertion also checks that the tolerance is
physically tight (far below the contact overlaps, ~1e-6 m, or the forces' size).
"""
from __future__ import annotations

import csv

import numpy as np
import pytest

from mpi_harness import run_under_mpi

EPS = np.finfo(float).eps
RANKS = (2, 3, 4)
SERIAL = "gas,gas_ulp,pgas,pgas_ulp,slide,slide_ulp,lost"
PARALLEL = "gas,pgas,shear,slide,slide_drop,pile,lost"

# Mirrors of the case script's constants (the scenes are defined there).
GAS_STEPS = 200
SLIDE_STEPS = 400
THRESHOLD = 1.2


@pytest.fixture(scope="module")
def results(tmp_path_factory):
    out = tmp_path_factory.mktemp("parallel")
    run_under_mpi(1, "parallel_cases.py", str(out), SERIAL, timeout=120)
    for ranks in RANKS:
        run_under_mpi(ranks, "parallel_cases.py", str(out), PARALLEL, timeout=120)

    def load(scenario, ranks):
        return np.load(out / f"{scenario}_{ranks}.npz")

    return load


# ----------------------------------------------------------------------------- 1. agreement
@pytest.mark.mpi
@pytest.mark.parametrize("scene", ["gas", "pgas"])
def test_rank_count_agreement(results, scene):
    """Dense colliding gas, 288 spheres, 200 steps (closed box; periodic in x and y): positions
    by id within the round-off bound, contact counts identical at every step, energies identical
    to round-off.  Rebuilds and migrations must have happened."""
    serial, perturbed = results(scene, 1), results(f"{scene}_ulp", 1)
    count = int(serial["count"])
    box_extent = float(np.max(serial["box"]))
    assert serial["contacts"][50:].min() > 30, "the scene must be colliding"
    assert int(serial["builds"]) >= 10, "the list must be rebuilt several times (migration happens then)"
    # Growth factor of a one-ulp seed on particle 0's x (~1.15 mm) over the run: measured 16 and 72 on two
    # machines (the gas is chaotic; numba compiles for the host CPU, so its round-off differs by machine).
    seed = np.spacing(1.15e-3)
    growth = max(1.0, float(np.abs(perturbed["positions"] - serial["positions"]).max()) / seed)
    position_tolerance = growth * np.spacing(box_extent) * count * GAS_STEPS  # ~3e-12 m
    assert position_tolerance < 1e-9, position_tolerance  # far below the overlaps (~1e-6 m)
    energy_scale = np.abs(serial["energies"]).max(axis=0)
    energy_growth = np.abs(perturbed["energies"] - serial["energies"]).max(axis=0)
    energy_tolerance = energy_growth * count * GAS_STEPS + EPS * count * GAS_STEPS * energy_scale
    # The bound must stay far below any energy that matters: within 1e-9 of each energy's scale (the rotational
    # energy's reached 1.1e-10 where the seed grew 72-fold).
    assert np.all(energy_tolerance <= 1e-9 * np.maximum(energy_scale, 1e-30) + 1e-25), energy_tolerance
    for ranks in RANKS:
        result = results(scene, ranks)
        assert int(result["count"]) == count
        difference = float(np.abs(result["positions"] - serial["positions"]).max())  # measured <= 9e-17 m
        assert difference <= position_tolerance, (ranks, difference, position_tolerance)
        assert np.array_equal(result["contacts"], serial["contacts"]), ranks
        energy_difference = np.abs(result["energies"] - serial["energies"]).max(axis=0)  # measured <= 2e-18 J
        assert np.all(energy_difference <= energy_tolerance), (ranks, energy_difference, energy_tolerance)
        assert int(result["builds"]) == int(serial["builds"])
        assert int(result["owner_changes"]) > 10, "particles must migrate between ranks"


# ----------------------------------------------------------------------------- 2. migration stress
@pytest.mark.mpi
def test_shear_flow_every_particle_crosses_many_times(results):
    """Plug + shear flow along a periodic x channel (3 +- 1 m/s, ~3 periods in 400 steps): every
    particle changes rank at least 3 times; no particle is lost, duplicated or orphaned."""
    for ranks in RANKS:
        result = results("shear", ranks)
        total = int(result["total"])
        assert np.all(result["counts"] == total), ranks
        assert int(result["duplicates"]) == 0, ranks  # each id owned by exactly one rank, every step
        assert int(result["lost"]) == 0 and bool(result["finite"]), ranks
        # Slowest particles (2 m/s) travel ~2 periods; a period holds >= 2 rank changes per x slab pair.
        assert result["changes"].min() >= 3, (ranks, result["changes"].min())
        assert result["changes"].mean() >= 2 * ranks, (ranks, result["changes"].mean())


@pytest.mark.mpi
def test_sliding_contact_history_survives_migration(results):
    """Two spheres sliding in a wall corner, pressed together and against floor and wall: the pair
    straddles an RCB cut, then B migrates while in contact and slipping.  The contact forces on
    both spheres and the wall forces match serial at every step on 2, 3 and 4 ranks; dropping the
    migrating contact records (negative control) changes them by a third of their size."""
    serial, perturbed = results("slide", 1), results("slide_ulp", 1)
    names = ("forces_a", "forces_b", "floor", "side")
    particles = 4
    for ranks in RANKS:
        result = results("slide", ranks)
        changes = np.flatnonzero(np.diff(result["owner_b"]))
        assert len(changes), (ranks, "B must change rank")
        step = changes[-1] + 1
        assert result["gaps"][step] < 0.0, "B migrates while touching A"
        slip = abs(result["velocity_a"][step, 0] - result["velocity_b"][step, 0])
        assert slip > 0.01, ("the A-B contact slips when B migrates", slip)  # ~0.05 m/s
        for name in names:
            scale = float(np.abs(serial[name]).max())
            # One position-ulp seed's effect on this force (measured), union bound over particles and
            # steps, plus the reordering of <= 4 force terms (4 eps |F|).
            growth = float(np.abs(perturbed[name] - serial[name]).max())
            tolerance = growth * particles * SLIDE_STEPS + 4 * EPS * scale
            assert tolerance < 1e-9 * scale, (name, tolerance, scale)
            difference = float(np.abs(result[name] - serial[name]).max())  # measured 0 (pair), 4e-19 N (walls)
            assert difference <= tolerance, (ranks, name, difference, tolerance)
            control = float(np.abs(results("slide_drop", ranks)[name] - serial[name]).max())
            if name in ("forces_a", "forces_b"):
                assert control > 0.05 * scale, (ranks, name, control, scale)  # measured 0.17-0.33 of scale
                assert control > 1e6 * tolerance


# ----------------------------------------------------------------------------- 3. load balance
@pytest.mark.mpi
def test_pile_in_a_corner_is_rebalanced(results):
    """320 spheres spread over a 24 x 24 x 15 mm box pile into the corner (0, 0, 0): the first
    partition becomes imbalanced; the system rebalances (logged with before -> after) and ends
    with the measured imbalance below parallel.rebalance_threshold."""
    for ranks in RANKS:
        result = results("pile", ranks)
        assert int(result["count"]) == int(result["total"])
        positions = result["positions"]
        # The lattice's centroid is (12, 12, 7.5) mm; a close-packed heap of 320 spheres in the corner
        # has its centroid near (6.5, 6.5, 5) mm (measured 6.6, 6.6, 4.9).
        assert np.all(result["centroid"] < np.array([7.5e-3, 7.5e-3, 6e-3])), result["centroid"]
        # Particle counts per box of the initial partition, for the piled positions.
        boxes = result["initial_boxes"]
        inside = np.all((positions[:, None, :] >= boxes[None, :, 0]) & (positions[:, None, :] < boxes[None, :, 1]),
                        axis=2)
        counts = inside.sum(axis=0)
        assert counts.max() / counts.mean() > THRESHOLD, counts  # the pile unbalanced the first partition
        assert int(result["rebalances"]) >= 2, "the imbalance must have triggered a rebalance"
        before, after = result["last_imbalance"]
        assert before > THRESHOLD and after < THRESHOLD, (ranks, before, after)
        messages = [m for m in result["messages"] if m.startswith("rebalance")]
        assert len(messages) == int(result["rebalances"]), messages
        assert "->" in messages[-1] and f"{after:.3f}" in messages[-1], messages[-1]
        # Between rebuilds the cost drifts; the last check found it below the threshold.
        assert all(imbalance < THRESHOLD + 0.1 for imbalance in result["history"][-5:, 1])
        # Each rank's cost total as the check forms it (counts of owned particles, pair ends and touching pair ends)
        # is the per-particle costs' sum: integers times the cost weights, exact in floating point.
        exact, estimated = result["cost_totals"].T
        assert np.all(exact > 0) and np.array_equal(exact, estimated), result["cost_totals"]


# ----------------------------------------------------------------------------- 4. lost particles
@pytest.mark.mpi
def test_lost_particles_are_removed_and_counted(results):
    """12 spheres fly out through the bounded domain's x = 20 mm face: all 12 are removed and counted
    (history.csv lost_particles), no id is duplicated, nothing stays NaN.  A particle that goes NaN
    (as after a blow-up) stops the run at once with exit 3 (the run monitor); stepping on, the
    rebuild removes and counts it."""
    for ranks in (1,) + RANKS:
        result = results("lost", ranks)
        total, escaping = int(result["total"]), int(result["escaping"])
        assert int(result["lost"]) == escaping, (ranks, int(result["lost"]))
        assert int(result["count"]) == total - escaping
        ids = result["ids"]
        assert len(np.unique(ids)) == len(ids)
        assert np.all(ids < total - escaping), "the escaping particles are removed"
        assert bool(result["finite"])
        with open(str(result["history"])) as handle:
            rows = list(csv.DictReader(handle))
        lost = [int(float(row["lost_particles"])) for row in rows]
        particles = [int(float(row["particles"])) for row in rows]
        assert lost[-1] == escaping and lost == sorted(lost)
        assert all(p + n == total for p, n in zip(particles, lost))
        for row in rows:
            assert all(np.isfinite(float(value)) for value in row.values()), row
        # The NaN particle: the run stopped before its first step, on every rank.
        stopped = str(result["stopped"])
        assert stopped.startswith("run stopped at step 0") and "non-finite energies" in stopped, stopped
        blown_ids = result["blown_ids"]
        assert 0 not in blown_ids and len(blown_ids) == total - 1, "the NaN particle (id 0) is removed"
        assert int(result["blown_lost"]) == 1 and int(result["blown_nonfinite"]) == 1
        assert bool(result["blown_finite"])


def test_rows_near_box_selects_what_box_distance_selects():
    """The ghost selection's one-pass kernel against box_distance's numpy arithmetic: the same rows, also for
    boxes open to infinity, shifted (periodic) images, points on the cutoff and non-finite points."""
    from pdemfem.parallel.decomposition import box_distance, rows_near_box

    rng = np.random.default_rng(17)
    points = rng.uniform(-2.0, 3.0, (5000, 3))
    points[10] = [np.nan, 0.5, 0.5]
    points[11] = [np.inf, 0.5, 0.5]
    points[12] = [1.25, 0.5, 0.5]  # exactly the cutoff beyond the upper x face
    for lower, upper in (([0.0, 0.0, 0.0], [1.0, 1.0, 1.0]), ([-np.inf, 0.0, -np.inf], [1.0, np.inf, np.inf])):
        lower, upper = np.array(lower), np.array(upper)
        for shift in (np.zeros(3), np.array([-2.5, 0.0, 0.0])):
            expected = np.flatnonzero(box_distance(points + shift, lower, upper) < 0.25)
            assert np.array_equal(rows_near_box(points, shift, lower, upper, 0.25), expected)
            assert 0 < len(expected) < len(points)


def test_histogram_cuts_find_the_weighted_median():
    """The cut search against the exact weighted median (numpy sort and cumulative sum), for several regions
    split at once, particles of finished regions (slot -1) left out, weights spanning many magnitudes, a heap
    of particles at one coordinate and a region without weight.  The cut must lie in the last round's bin that
    holds the median: within (high - low) / CUT_BINS**CUT_ROUNDS of the median particle's coordinate."""
    from mpi4py import MPI

    from pdemfem.parallel.decomposition import CUT_BINS, CUT_ROUNDS, _axes_and_cuts

    rng = np.random.default_rng(5)
    count = 4
    particle_slot = rng.integers(-1, count - 1, 20000)  # slot 3 has no particles
    coordinate = rng.uniform(0.0, 1.0, 20000) ** 3  # crowded near 0
    coordinate[particle_slot == 1] = np.where(rng.uniform(size=np.count_nonzero(particle_slot == 1)) < 0.6,
                                              0.25, coordinate[particle_slot == 1])  # 60 % at one coordinate
    weights = rng.uniform(0.0, 1.0, 20000) * 10.0 ** rng.integers(-3, 4, 20000)
    fractions = np.array([0.5, 0.5, 1.0 / 3.0, 0.5])
    # The same coordinate along all three axes and a unit cube per region: every axis scores alike and the
    # cut goes along x, the search under test.
    positions = np.ascontiguousarray(np.repeat(coordinate[:, None], 3, axis=1))
    axes, cuts, _ = _axes_and_cuts(MPI.COMM_SELF, particle_slot, positions, weights, np.zeros((count, 3)),
                                   np.ones((count, 3)), fractions, 0.0)
    assert np.all(axes == 0)
    resolution = 1.0 / CUT_BINS ** CUT_ROUNDS
    for slot in range(count - 1):
        mine = particle_slot == slot
        order = np.argsort(coordinate[mine], kind="stable")
        cumulative = np.cumsum(weights[mine][order])
        median = coordinate[mine][order][np.searchsorted(cumulative, fractions[slot] * cumulative[-1], side="right")]
        assert abs(cuts[slot] - median) <= resolution * (1 + 1e-9), (slot, cuts[slot], median)
        # The weight below the cut misses the target by at most the weight in that last bin (the cut goes
        # through it linearly, as if its weight were spread evenly).
        below = weights[mine][coordinate[mine] < cuts[slot]].sum()
        in_last_bin = weights[mine][np.abs(coordinate[mine] - median) <= resolution].sum()
        assert abs(below - fractions[slot] * cumulative[-1]) <= in_last_bin * (1 + 1e-12), (slot, below)
    assert cuts[3] == 0.5  # no weight: the region is halved


def test_cut_axis_keeps_both_sides_alike_and_otherwise_the_longest():
    """The axis choice (_axes_and_cuts): a bed cut across gravity at its cost median would give the loose upper
    side most of the particles; an upright cut gives each side its share of both, so it is chosen.  A uniform
    cloud is cut along its longest axis (the smallest interface); a cutoff that makes the cut's ghosts costly
    never turns it to a shorter axis."""
    from mpi4py import MPI

    from pdemfem.parallel.decomposition import _axes_and_cuts

    rng = np.random.default_rng(11)
    dense = rng.uniform([0, 0, 0], [1, 1, 0.5], (6000, 3))
    loose = rng.uniform([0, 0, 0.5], [1, 1, 2.0], (6000, 3))
    positions = np.ascontiguousarray(np.vstack([dense, loose]))
    weights = np.concatenate([np.full(6000, 5.0), np.full(6000, 1.0)])  # contacts make the bed's particles dear
    slot = np.zeros(len(positions), dtype=np.int64)
    lows, highs = positions.min(axis=0)[None, :], positions.max(axis=0)[None, :]
    axes, cuts, _ = _axes_and_cuts(MPI.COMM_SELF, slot, positions, weights, lows, highs, np.array([0.5]), 0.05)
    assert axes[0] in (0, 1), axes  # z (the longest, index 2) would put 5/6 of the particles above the cut
    below = positions[:, axes[0]] < cuts[0]
    assert abs(weights[below].sum() / weights.sum() - 0.5) < 0.01  # still the cost median
    assert abs(np.count_nonzero(below) / len(positions) - 0.5) < 0.02  # and about half the particles
    uniform = np.ascontiguousarray(rng.uniform([0, 0, 0], [1, 1, 1.3], (12000, 3)))
    for cutoff in (0.0, 0.05, 0.3):
        axes, _, _ = _axes_and_cuts(MPI.COMM_SELF, slot, uniform, np.ones(12000), uniform.min(axis=0)[None, :],
                                    uniform.max(axis=0)[None, :], np.array([0.5]), cutoff)
        assert axes[0] == 2, (cutoff, axes)

"""Clumps on several ranks: bodies owned by the rank of their centre, members ghosted across the cuts,
whole bodies migrating; 1, 2 and 3 ranks agree, and checkpoints restart on any rank count.

The case (mpi_cases/clump_agreement.py): 24 three-sphere clumps thrown from both ends of a long box
towards its middle onto a floor, 2000 steps (they meet from step ~1000 on); the RCB cuts along x run
through the clumps that meet there (the case reports the members held as ghosts and those sticking out of their owner's box).
"""
from __future__ import annotations

import numpy as np
import pytest

from mpi_harness import run_under_mpi

STEPS = 2000
FIELDS = ("positions", "orientations", "velocities", "angular_velocities", "member_positions")


def _run(tmp_path, ranks, name, *extra):
    out = tmp_path / f"{name}.npz"
    run_under_mpi(ranks, "clump_agreement.py", str(out), str(STEPS), *extra)
    return np.load(out)


def _tolerances(serial, perturbed):
    """Per field: the growth of a one-ulp shift of every body over the run, times the steps (each
    step of another rank count may sum a member's contact forces in another order, a perturbation
    of the same size, and the growth is at most additive over the steps), plus 100 ulp of the scale."""
    tolerances = {}
    for name in FIELDS:
        scale = float(np.abs(serial[name]).max())
        growth = float(np.abs(perturbed[name] - serial[name]).max())
        tolerances[name] = growth * STEPS + 100.0 * np.spacing(scale)
    return tolerances


@pytest.fixture(scope="module")
def serial_reference(tmp_path_factory):
    """(serial run, its round-off tolerances) shared by the tests."""
    folder = tmp_path_factory.mktemp("clump_serial")
    serial = _run(folder, 1, "serial")
    perturbed = _run(folder, 1, "ulp", "ulp")
    return serial, _tolerances(serial, perturbed)


@pytest.fixture(scope="module")
def two_ranks(tmp_path_factory):
    """(folder, result) of the 2-rank run, writing a checkpoint every 1000 steps."""
    folder = tmp_path_factory.mktemp("clump_two_ranks")
    return folder, _run(folder, 2, "full", "checkpoint", "1000")


@pytest.mark.mpi
def test_clumps_agree_on_one_two_and_three_ranks(tmp_path, serial_reference, two_ranks):
    serial, tolerances = serial_reference
    assert int(serial["contacts"]) > 5, "the clumps must be touching when compared"
    # Physically tight: far below the contact overlaps (~1e-6 m).
    assert tolerances["positions"] < 1e-9, tolerances
    for ranks in (2, 3):
        result = two_ranks[1] if ranks == 2 else _run(tmp_path, ranks, f"ranks{ranks}")
        assert result["ghost_members"] > 0 and result["members_outside"] > 0  # the cuts run through clumps
        assert np.array_equal(result["ids"], serial["ids"])
        assert np.array_equal(result["member_ids"], serial["member_ids"])
        assert int(result["contacts"]) == int(serial["contacts"])
        for name in FIELDS:
            difference = float(np.abs(result[name] - serial[name]).max())
            print(f"{ranks} ranks, {name}: {difference:.3g} (tolerance {tolerances[name]:.3g})")
            assert difference <= tolerances[name], (ranks, name, difference, tolerances[name])


@pytest.mark.mpi
def test_clump_checkpoint_restarts_bit_identically_and_on_other_rank_counts(tmp_path, serial_reference, two_ranks):
    """Checkpoints every 1000 steps on 2 ranks; restarted from step 1000 on 2 ranks: bit-identical to
    the uninterrupted run (the stored decomposition is used); on 3 ranks the rows are re-partitioned,
    so the sums may run in another order: within the round-off tolerance of the test above."""
    folder, full = two_ranks
    assert int(full["step"]) == STEPS
    checkpoint = folder / "full" / "checkpoints" / "checkpoint_000000001000.h5"
    assert checkpoint.is_file()
    again = _run(tmp_path, 2, "again", "restart", str(checkpoint))
    for name in FIELDS:
        assert np.array_equal(again[name], full[name]), name
    _, tolerances = serial_reference
    for ranks in (3,):
        other = _run(tmp_path, ranks, f"other{ranks}", "restart", str(checkpoint))
        assert np.array_equal(other["ids"], full["ids"])
        for name in FIELDS:
            difference = float(np.abs(other[name] - full[name]).max())
            print(f"restart on {ranks} rank(s), {name}: {difference:.3g} (tolerance {tolerances[name]:.3g})")
            assert difference <= tolerances[name], (ranks, name, difference)

"""Parallel agreement of the DEM step on 1, 2 and 3 ranks.

The same dense colliding scene (200 spheres thrown into a box, friction, damping,
size spread) runs for STEPS steps on 1, 2 and 3 ranks; results are gathered by
particle id.  Ranks change only the order in which contact forces are summed
(per-rank partial sums reduced with Allreduce, or ghost/owner copies), i.e. a
relative round-off of ~1e-16 per force per step.  In a dense granular flow such
perturbations grow exponentially (collisions amplify them), so the tolerance is
measured rather than guessed: a serial run whose particles are all displaced by one
unit in the last place (one round-off each) diverges from the unperturbed run by D
after STEPS steps.  The rank-count runs inject round-off of at most that size into
every particle at every step, i.e. STEPS such perturbations, each growing at most
like the first; their divergence is bounded by D * STEPS (a union bound over the
steps), plus 100 ulp of the box size for the unamplified part.
"""
from __future__ import annotations

import numpy as np
import pytest

from mpi_harness import run_under_mpi

STEPS = 1500  # ~0.02 s: the fall and first collisions, ~60 contacts
PARTICLES = 200
BOX = 0.012


def _run(tmp_path, ranks, *extra):
    out = tmp_path / f"dem_{ranks}_{'_'.join(extra) or 'plain'}.npz"
    run_under_mpi(ranks, "dem_agreement.py", str(out), str(STEPS), *extra)
    return np.load(out)


@pytest.mark.mpi
def test_dem_rank_count_agreement(tmp_path):
    serial = _run(tmp_path, 1)
    perturbed = _run(tmp_path, 1, "ulp")
    assert serial["contacts"] > 20, "the scene must be colliding when compared"
    growth = float(np.abs(perturbed["positions"] - serial["positions"]).max())
    floor = 100.0 * np.spacing(BOX)
    position_tolerance = growth * STEPS + floor
    # Wall forces: the same growth measured on the wall forces, same union bound.
    force_scale = float(np.abs(serial["wall_forces"]).max())
    force_growth = float(np.abs(perturbed["wall_forces"] - serial["wall_forces"]).max())
    force_tolerance = force_growth * STEPS + 1e-13 * force_scale
    # The tolerance must still be physically tight: far below the contact overlaps (~1e-6 m).
    assert position_tolerance < 1e-9, position_tolerance
    for ranks in (2, 3):
        result = _run(tmp_path, ranks)
        assert np.array_equal(result["ids"], serial["ids"])
        difference = float(np.abs(result["positions"] - serial["positions"]).max())
        assert difference <= position_tolerance, (ranks, difference, position_tolerance)
        assert int(result["contacts"]) == int(serial["contacts"])
        force_difference = float(np.abs(result["wall_forces"] - serial["wall_forces"]).max())
        assert force_difference <= force_tolerance, (ranks, force_difference, force_tolerance)


@pytest.mark.mpi
def test_heat_rank_count_agreement(tmp_path):
    """The same scene with heat on (a 400 K floor, grains at 300 K, conduction at every contact):
    temperatures on 2 and 3 ranks agree with 1 rank within the round-off growth measured the same way
    (a one-ulp nudge of the positions, union bound over the steps), and the floor's heat ledger too."""
    serial = _run(tmp_path, 1, "heat")
    perturbed = _run(tmp_path, 1, "ulp", "heat")
    temperatures = serial["temperatures"]
    assert temperatures.max() > 300.0 + 1.0, "heat must have moved for the comparison to mean something"
    growth = float(np.abs(perturbed["temperatures"] - temperatures).max())
    tolerance = growth * STEPS + 100.0 * np.spacing(400.0)
    assert tolerance < 1e-4, tolerance  # 1e-6 of the 100 K that can move: a tight comparison
    heat_growth = float(np.abs(perturbed["heat_given"] - serial["heat_given"]).max())
    heat_tolerance = heat_growth * STEPS + 1e-13 * float(np.abs(serial["heat_given"]).max())
    for ranks in (2, 3):
        result = _run(tmp_path, ranks, "heat")
        difference = float(np.abs(result["temperatures"] - temperatures).max())
        assert difference <= tolerance, (ranks, difference, tolerance)
        heat_difference = float(np.abs(result["heat_given"] - serial["heat_given"]).max())
        assert heat_difference <= heat_tolerance, (ranks, heat_difference, heat_tolerance)

"""The DEM step makes at most two collectives over the ranks: one MAX (the displacement that decides
the list rebuild) and one SUM (energies, contact count, plane-wall forces, every mesh/cylinder wall's
and solid surface's totals in one buffer); where the SUM is left pending to the next step (scenes
without FE solids), one: an Allgather that carries both.  pdemfem.parallel.reductions explains why the
count matters.

Counted on 2 ranks by tests/mpi_cases/collectives_case.py, which runs the simulation on a communicator
class that counts every mpi4py collective call, one `Simulation.step` at a time.  Not counted, by
design: the run loop's stop checks (one Allreduce every STOP_CHECK_EVERY steps) and output steps (the
history row's reductions), and steps that rebuild the neighbour list (migration: Alltoall/Alltoallv of
particles and contact records, the lost-particle count, the imbalance Allgather).  The coupled scene
advances its FE plate every step (fem_every 1): the FE sub-steps add no mpi4py reduction (their
external-work diagnostic is summed over the ranks when read); PETSc's own communication (the mass
matrix products' ghost scatters, the contact surface gather, the blow-up norm every BLOWUP_CHECK_EVERY
FE steps) is recorded in the case's output but not asserted here.  The heated scene (heat on in the
coupled one) adds none: temperatures ride the ghost exchange, the walls' heat is summed only when read.
"""
from __future__ import annotations

import json

import pytest

from mpi_harness import run_under_mpi

STEPS = 12
CALLS, STEPS_PER_CALL = 12, 7  # as in mpi_cases/deferred_sum_case.py


@pytest.mark.mpi
@pytest.mark.parametrize("kind", ["planes", "walls", "coupled", "heated"])
def test_a_dem_step_makes_at_most_two_collectives(kind, tmp_path):
    out = tmp_path / "counts.json"
    run_under_mpi(2, "collectives_case.py", kind, out, STEPS)
    result = json.loads(out.read_text())
    assert result["contacts"] > 0  # the step computed contacts (pairs, walls, the plate) while counted
    plain_steps = [step for step in result["steps"] if not step["rebuild"]]
    assert len(plain_steps) >= STEPS // 2
    counts = [sum(step["mpi4py"].values()) for step in plain_steps]
    # At least the MAX: the counter sees the step's collectives (a count of 0 would be a broken counter).
    assert min(counts) >= 1, counts
    assert max(counts) <= 2, [step["mpi4py"] for step in plain_steps]
    # Buffer-based, nothing pickled.
    assert all(set(step["mpi4py"]) <= {"Allreduce", "Allgather"} for step in plain_steps)
    # Within one call of several steps, where the scene leaves the SUM pending until the next step's MAX (no
    # solids), both travel in one Allgather: one collective per step (the call's first step has no SUM
    # pending: the call before finished it).
    in_call = [step for step in result["steps_in_one_call"][1:] if not step["rebuild"]]
    assert len(in_call) >= STEPS // 2
    if kind in ("planes", "walls"):
        assert all(step["mpi4py"] == {"Allgather": 1} for step in in_call), in_call
    else:
        assert max(sum(step["mpi4py"].values()) for step in in_call) <= 2, in_call


@pytest.mark.mpi
def test_a_sum_left_in_flight_to_the_next_step_gives_the_same_results_bit_for_bit(tmp_path):
    """Every value read between steps that comes from the step's SUM (energies, contact count, the walls'
    forces, torques and work, the history's mean surface forces) is identical with the SUM finished at once,
    and with the ghosts' update finished before the forces instead of overlapping the owned pairs."""
    out = tmp_path / "deferred.json"
    run_under_mpi(2, "deferred_sum_case.py", out)
    result = json.loads(out.read_text())
    deferred_steps, finished_steps = result["steps_in_flight"]
    # The deferred run left every step's SUM in flight past its forces, the other none.
    assert deferred_steps == CALLS * STEPS_PER_CALL and finished_steps == 0
    assert result["deferred"] == result["finished"]
    contact_counts = [row[4] for row in result["deferred"]]
    assert max(contact_counts) > 0
    # The ghosts' update finished before the forces: the same, bit for bit, with pairs across the cut there.
    assert result["boundary_pairs"] > 0
    assert result["serial_ghosts"] == result["deferred"]
    # The SUM as an Iallreduce (more ranks than StepReductions gathers on): the same on 2 ranks.
    assert result["iallreduce"] == result["deferred"]

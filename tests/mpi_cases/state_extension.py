"""MPI case: a wall kind and per-particle fields the checkpoint code has never heard of survive a
restart bit-identically, and a ghost_step field reaches the ghosts every step.

    state_extension.py OUT

`ProbeWall` is a new contributor wall kind defined only here, with its own state (a step
counter, in its state_dict) and two per-particle fields registered through the field
registry: "probe:tag" (carried by ghosts every step: [id / 2, the probe's step]) and
"probe:low_steps" (migrates only: steps each particle spent below z = 0.04 m).  The run
goes STEPS steps with a checkpoint at CHECKPOINT; a second simulation restores that
checkpoint and continues.  Prints "OK <ranks> <ghost rows checked>" on rank 0.
"""
import sys
from pathlib import Path

sys.path.insert(0, str(Path(__file__).parent))
import pdemfem  # noqa: E402,F401
import numpy as np  # noqa: E402
from mpi4py import MPI  # noqa: E402

import restart_scenes  # noqa: E402
from pdemfem import state_dict as kinds  # noqa: E402
from pdemfem.simulation import Simulation  # noqa: E402
from pdemfem.walls.base import ContributorWall  # noqa: E402

STEPS, CHECKPOINT = 80, 40
LOW = 0.04  # m: a height the grains cross within the run


class ProbeWall(ContributorWall):
    """Exerts no force; checks and writes its per-particle fields every step."""

    def __init__(self):
        super().__init__("probe")
        self.steps = 0
        self.ghost_rows_checked = 0
        self.ghost_mismatches = 0

    def move(self, dt: float) -> None:
        self.steps += 1

    def add_forces(self, system, first: int, last: int):
        state = system.state
        if "probe:tag" not in state.fields:
            state.add_field("probe:tag", (2,), ghost_rebuild=True, ghost_step=True)
        tag = state.fields["probe:tag"]
        low_steps = self._field(state, "probe:low_steps", (), np.int64, 0)
        ghosts = slice(state.owned_count, state.count)
        if self.steps >= 2:  # the field is registered at step 1: from step 2 on every ghost has it
            expected = np.column_stack([0.5 * state.ids[ghosts], np.full(state.ghost_count, self.steps - 1.0)])
            self.ghost_mismatches += int(np.count_nonzero(np.any(tag[ghosts] != expected, axis=1)))
            self.ghost_rows_checked += state.ghost_count
        tag[first:last, 0] = 0.5 * state.ids[first:last]
        tag[first:last, 1] = self.steps
        low_steps[first:last] += state.positions[first:last, 2] < LOW
        return 0.0, 0.0, 0

    def state_dict(self) -> dict:
        state = super().state_dict()
        state["steps"] = kinds.scalar(self.steps)
        return state

    def load_state_dict(self, state: dict) -> None:
        super().load_state_dict(state)
        self.steps = int(state["steps"])


def build(out: Path, comm) -> tuple:
    scene = restart_scenes.pile_scene(out, STEPS, CHECKPOINT, CHECKPOINT, count=64)
    del scene["solids"], scene["coupling"]  # no plate: the particles and their walls are the subject
    simulation = Simulation.from_dict(scene, comm=comm, base_dir=out)
    probe = ProbeWall()
    simulation.contributor_walls.append(probe)
    simulation.particle_system.contributors.append(probe)
    return simulation, probe


def finish(simulation, probe, comm) -> tuple:
    simulation.run(progress=False)
    state = restart_scenes.gather_state(simulation)
    checked = comm.allreduce(probe.ghost_rows_checked)
    mismatches = comm.allreduce(probe.ghost_mismatches)
    assert mismatches == 0, f"{mismatches} ghost rows of probe:tag were stale"
    return state, checked


comm = MPI.COMM_WORLD
out = Path(sys.argv[1])
simulation, probe = build(out, comm)
uninterrupted, checked = finish(simulation, probe, comm)
assert probe.steps == STEPS
simulation, probe = build(out, comm)
simulation.io.restore(out / "checkpoints" / f"checkpoint_{CHECKPOINT:012d}.h5")
assert probe.steps == CHECKPOINT
restarted, checked_after_restart = finish(simulation, probe, comm)
if comm.rank == 0:
    assert sorted(uninterrupted) == sorted(restarted)
    assert "field:probe:tag" in restarted and "field:probe:low_steps" in restarted
    low_steps = restarted["field:probe:low_steps"]
    assert np.any((low_steps > 0) & (low_steps < STEPS)), "no grain crossed z = LOW: the field is untested"
    for key in uninterrupted:
        assert np.array_equal(uninterrupted[key], restarted[key]), key
    print(f"OK {comm.size} {checked} {checked_after_restart}")

"""MPI case: an insertion rebuild keeps the last step's forces of particles that change rank.

usage: stream_forces_case.py OUT_DIR
A stream pours onto a floor; with the rebalance threshold at 1 every insertion rebuild
re-partitions, so particles migrate.  At each insertion the forces and torques of the particles
present before it are gathered by id before and after (ParticleSystem.add_particles): the next
step's first half kick needs them unchanged.  Prints "migrated N compared M" on rank 0 and exits 1
on a difference.
"""
import sys
from pathlib import Path

import numpy as np

sys.path.insert(0, str(Path(__file__).parent))
import pdemfem  # noqa: F401,E402  (environment first)
from mpi4py import MPI  # noqa: E402

from stream_scenes import pile_stream  # noqa: E402
from pdemfem import Simulation  # noqa: E402


def by_id(system):
    state = system.state
    owned = state.owned_count
    rows = system.comm.allgather((state.ids[:owned].copy(), state.forces[:owned].copy(),
                                  state.torques[:owned].copy(), np.full(owned, system.comm.rank)))
    ids = np.concatenate([r[0] for r in rows])
    order = np.argsort(ids)
    return ids[order], *(np.concatenate([r[k] for r in rows])[order] for k in (1, 2, 3))


def main():
    out = sys.argv[1]
    comm = MPI.COMM_WORLD
    sim = Simulation.from_dict(pile_stream(out, 0.02, 0.01), comm=comm, output_dir=out)
    system = sim.particle_system
    system.rebalance_threshold = 1.0
    original = system.add_particles
    migrated, compared, failures = 0, 0, []

    def checked(new_state):
        nonlocal migrated, compared
        ids, forces, torques, ranks = by_id(system)
        original(new_state)
        after_ids, after_forces, after_torques, after_ranks = by_id(system)
        kept = np.isin(after_ids, ids)
        if not (np.array_equal(after_ids[kept], ids) and np.array_equal(after_forces[kept], forces)
                and np.array_equal(after_torques[kept], torques)):
            failures.append(sim.step_count)
        migrated += int(np.count_nonzero(after_ranks[kept] != ranks))
        compared += int(np.count_nonzero(np.any(forces != 0.0, axis=1)))

    system.add_particles = checked
    sim.step(int(round(0.02 / sim.dt)))
    if comm.rank == 0:
        print(f"migrated {migrated} compared {compared} failures {failures}")
    if failures:
        sys.exit(1)


if __name__ == "__main__":
    main()

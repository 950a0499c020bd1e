"""MPI case: a dense stream falling through an outlet, gathered by particle id (tests/test_streams.py).

usage: stream_case.py OUT_DIR RESULT.npz
Writes (rank 0) the ids, radii, positions and velocities of the particles present at the end (sorted
by id), the streams' and outlets' totals, and the stream's count after every step.
"""
import sys
from pathlib import Path

import numpy as np

sys.path.insert(0, str(Path(__file__).parent))
import pdemfem  # noqa: F401,E402  (environment first)
from mpi4py import MPI  # noqa: E402

from stream_scenes import falling_stream  # noqa: E402
from pdemfem import Simulation  # noqa: E402


def main():
    out, result = sys.argv[1], sys.argv[2]
    comm = MPI.COMM_WORLD
    sim = Simulation.from_dict(falling_stream(out, rate=2000.0), comm=comm, output_dir=out)
    steps = int(round(sim.scene.time.end / sim.dt))
    inserted = []
    for _ in range(steps):
        sim.step(1)
        inserted.append(sim.streams.inserted)
    p = sim.particles
    gathered = comm.gather((p.ids, p.radii, p.positions, p.velocities), root=0)
    totals = sim.stream_totals()
    count = sim.particle_count()
    if comm.rank == 0:
        ids = np.concatenate([g[0] for g in gathered])
        order = np.argsort(ids)
        np.savez(result, ids=ids[order], radii=np.concatenate([g[1] for g in gathered])[order],
                 positions=np.concatenate([g[2] for g in gathered])[order],
                 velocities=np.concatenate([g[3] for g in gathered])[order], inserted=np.array(inserted),
                 totals=np.array([totals["particles_in"], totals["mass_in"], totals["particles_out"],
                                  totals["mass_out"]]), count=count, ranks=comm.size)


if __name__ == "__main__":
    main()

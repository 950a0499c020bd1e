"""MPI case: the dense colliding DEM scene, gathered by particle id (tests/test_dem_parallel.py).

usage: dem_agreement.py OUT.npz STEPS [ulp] [heat]
Writes (rank 0) positions and velocities sorted by id, the contact count and every
wall force after STEPS steps.  "ulp" (serial only) shifts every particle by one unit
in the last place of its x coordinate before the run: the round-off growth reference
(a different summation order perturbs every particle's force by round-off).  "heat": the floor is
held at 400 K, the grains start at 300 K and conduct (a small heat capacity lets heat spread within
the run); the temperatures are written too.
"""
import sys
from pathlib import Path

import numpy as np

sys.path.insert(0, str(Path(__file__).parent))
import pdemfem  # noqa: F401,E402  (environment first)
from mpi4py import MPI  # noqa: E402

from dem_scenes import dense_scene  # noqa: E402
from pdemfem import Simulation  # noqa: E402


def main():
    out, steps = sys.argv[1], int(sys.argv[2])
    perturb = "ulp" in sys.argv[3:]
    comm = MPI.COMM_WORLD
    scene = dense_scene(count=200)
    if "heat" in sys.argv[3:]:
        scene["materials"]["glass"].update(conductivity=1.0, heat_capacity=5.0e-3)
        scene["particles"][0]["initial_temperature"] = 300.0
        scene["walls"][0]["temperature"] = 400.0
    sim = Simulation.from_dict(scene, comm=comm, output_dir=str(Path(out).parent / "unused"))
    if perturb:
        state = sim.particle_system.state
        owned = slice(0, state.owned_count)
        state.positions[owned, 0] += np.spacing(state.positions[owned, 0])
    sim.step(steps)
    p = sim.particles
    ids = comm.gather(p.ids, root=0)
    positions = comm.gather(p.positions, root=0)
    velocities = comm.gather(p.velocities, root=0)
    temperatures = comm.gather(p.temperatures if p.temperatures is not None else np.zeros(len(p.ids)), root=0)
    heat = sim.heat_given() if sim.particle_system.heat else {}
    walls = sim.particle_system.walls.names
    forces = np.array([sim.wall_force(name) for name in walls])
    contacts = sim.contact_count()
    if comm.rank == 0:
        ids = np.concatenate(ids)
        order = np.argsort(ids)
        np.savez(out, ids=ids[order], positions=np.concatenate(positions)[order],
                 velocities=np.concatenate(velocities)[order], wall_forces=forces, contacts=contacts,
                 temperatures=np.concatenate(temperatures)[order], heat_given=np.array(list(heat.values())),
                 ranks=comm.size, dt=sim.dt)


if __name__ == "__main__":
    main()

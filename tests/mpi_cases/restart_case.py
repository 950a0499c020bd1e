"""MPI case: uninterrupted run or restart of restart_scenes.pile_scene, final state to an .npz.

    restart_case.py OUT STEPS CHECKPOINT_STEPS RESULT.npz [--restart FILE] [--element P2] [--cohesive] [--heated] [--moving] [--free-axle]

The uninterrupted run writes checkpoints every CHECKPOINT_STEPS; with --restart the run
continues from FILE to the same end.  Rank 0 writes the state (sorted by id) to RESULT.npz.
"""
import sys
from pathlib import Path

sys.path.insert(0, str(Path(__file__).parent))
import pdemfem  # noqa: E402,F401
import numpy as np  # noqa: E402
from mpi4py import MPI  # noqa: E402

import restart_scenes  # noqa: E402
from pdemfem.simulation import Simulation  # noqa: E402

comm = MPI.COMM_WORLD
out, steps, checkpoint_steps, result = sys.argv[1], int(sys.argv[2]), int(sys.argv[3]), sys.argv[4]
restart = sys.argv[sys.argv.index("--restart") + 1] if "--restart" in sys.argv else None
element = sys.argv[sys.argv.index("--element") + 1] if "--element" in sys.argv else "P1"
scene = restart_scenes.pile_scene(out, steps, checkpoint_steps, checkpoint_steps, element=element)
if "--cohesive" in sys.argv:
    scene = restart_scenes.cohesive(scene)
if "--heated" in sys.argv:
    scene = restart_scenes.heated(scene)
if "--moving" in sys.argv:
    scene = restart_scenes.moving(scene)
if "--free-axle" in sys.argv:
    scene = restart_scenes.free_axle(scene)
with restart_scenes.cross_rank_static_solve():  # compared with other rank counts to round-off
    simulation = Simulation.from_dict(scene, comm=comm, base_dir=out, restart=restart)
simulation.run(progress=False)
state = restart_scenes.gather_state(simulation)
if comm.rank == 0:
    np.savez(result, **state)

"""MPI case: a stream pouring onto a floor, run through or restarted mid-stream (tests/test_streams.py).

    stream_restart_case.py OUT RESULT.npz [--restart FILE]

Rank 0 writes the final state (restart_scenes.gather_state, sorted by id) and the stream and outlet
totals to RESULT.npz.
"""
import sys
from pathlib import Path

sys.path.insert(0, str(Path(__file__).parent))
import pdemfem  # noqa: E402,F401
import numpy as np  # noqa: E402
from mpi4py import MPI  # noqa: E402

import restart_scenes  # noqa: E402
from stream_scenes import pile_stream  # noqa: E402
from pdemfem.simulation import Simulation  # noqa: E402

comm = MPI.COMM_WORLD
out, result = sys.argv[1], sys.argv[2]
restart = sys.argv[sys.argv.index("--restart") + 1] if "--restart" in sys.argv else None
simulation = Simulation.from_dict(pile_stream(out, 0.02, 0.005), comm=comm, output_dir=out, restart=restart)
simulation.run(progress=False)
state = restart_scenes.gather_state(simulation)
totals = simulation.stream_totals()
if comm.rank == 0:
    np.savez(result, totals=np.array([totals[key] for key in sorted(totals)]), **state)

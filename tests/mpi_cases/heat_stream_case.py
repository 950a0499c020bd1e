"""MPI case: the heated pour (stream_scenes.heated_pile_stream) run to its end (tests/test_heat_carried.py).

usage: heat_stream_case.py OUT RESULT.json
Writes history.csv to OUT and (rank 0) RESULT.json: the heat content each rank booked as carried in and out
(so the test sees that both ranks inserted and removed grains), the mass inserted and the mass still present,
as of the last history row.
"""
import json
import sys
from pathlib import Path

import numpy as np

sys.path.insert(0, str(Path(__file__).parent))
import pdemfem  # noqa: F401,E402  (environment first)
from mpi4py import MPI  # noqa: E402

from stream_scenes import heated_pile_stream  # noqa: E402
from pdemfem import Simulation  # noqa: E402


def main():
    out, result = sys.argv[1], sys.argv[2]
    comm = MPI.COMM_WORLD
    sim = Simulation.from_dict(heated_pile_stream(out), comm=comm, output_dir=out)
    ledger = sim.particle_system.carried_heat
    booked = np.zeros(2)  # this rank's bookings, in and out, as they happen
    book_in, book_out = ledger.book_in, ledger.book_out

    def counted_in(heat):
        booked[0] += heat
        book_in(heat)

    def counted_out(heat):
        booked[1] += heat
        book_out(heat)

    ledger.book_in, ledger.book_out = counted_in, counted_out
    # The books as the last history row saw them: the checkpoint written after it (the run's end) puts the
    # state in the order a restart starts from, and that rebuild removes the grains that left in the last steps
    # (a restart removes them alike); the row before it still counts them as present.
    at_row = {"booked": booked.copy(), "present": 0.0}
    write_output = sim.io.write_output

    def written_row():
        write_output()
        state = sim.particle_system.state
        at_row["booked"] = booked.copy()
        at_row["present"] = comm.allreduce(float(np.sum(state.mass[:state.owned_count])))

    sim.io.write_output = written_row
    sim.run(progress=False)
    present = at_row["present"]
    per_rank = comm.gather(at_row["booked"].tolist(), root=0)
    if comm.rank == 0:
        Path(result).write_text(json.dumps({"booked": per_rank, "mass_in": sim.stream_totals()["mass_in"],
                                            "mass_present": present, "steps": sim.step_count}))


if __name__ == "__main__":
    main()

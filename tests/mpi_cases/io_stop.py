"""MPI case: a step loop that stops on a signal delivered to some ranks only.

    io_stop.py DIR

Each rank writes its pid to DIR/pid.<rank>, then loops (a "step" = a 2 ms sleep),
checking StopRequest.should_stop every 5 steps.  After the stop every rank writes the
final checkpoint collectively and DIR/stopped.<rank> = "<step> <signal name or ->".
Gives up after 60 s (then the test fails: the flag was not seen).
"""
import sys
import time
from pathlib import Path

import numpy as np

import pdemfem  # noqa: F401
from mpi4py import MPI  # noqa: E402

from pdemfem.io.checkpoint import checkpoint_path, write_checkpoint  # noqa: E402
from pdemfem.io.signals import StopRequest  # noqa: E402

comm = MPI.COMM_WORLD
out = Path(sys.argv[1])
stop = StopRequest()
(out / f"pid.{comm.rank}.tmp").write_text(str(__import__("os").getpid()))
(out / f"pid.{comm.rank}.tmp").rename(out / f"pid.{comm.rank}")
step, started = 0, time.monotonic()
while time.monotonic() - started < 60.0:
    time.sleep(0.002)
    step += 1
    if step % 5 == 0 and stop.should_stop(comm):
        break
ids = np.arange(comm.rank * 10, comm.rank * 10 + 10, dtype=np.int64)
write_checkpoint(checkpoint_path(out, step), comm, {"ids": ids, "positions": np.zeros((10, 3))},
                 attributes={"step": step, "time": step * 1e-3, "scene_hash": "h"}, keep=2)
(out / f"stopped.{comm.rank}").write_text(f"{step} {stop.signal_name or '-'}")
stop.restore()

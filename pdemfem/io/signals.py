"""Stop requests from batch schedulers: finish the step, checkpoint together, exit cleanly.

    stop = StopRequest()                       # installs SIGTERM and SIGUSR1 handlers
    for step in ...:
        advance()
        if step % STOP_CHECK_EVERY == 0 and stop.should_stop(comm):   # collective
            write_checkpoint(...); break
    stop.restore()

Schedulers send SIGTERM (or a configured signal such as SIGUSR1, e.g. Slurm's
``--signal=USR1@300``) some time before the wall-time limit.  The handler only sets a
flag (nothing else is safe inside a signal handler, and the step in progress must
finish).  The signal may reach only some ranks (or reach them at different steps), so
`should_stop` combines the flags with an Allreduce(MAX): every rank sees the same
answer at the same step, writes the final checkpoint collectively and exits.  Call it
every N steps (one 4-byte Allreduce, ~microseconds; N = 100 keeps the cost invisible
and the reaction time far below a scheduler's grace period).

Open MPI's mpirun forwards SIGUSR1 and SIGUSR2 to all ranks; a SIGTERM sent to mpirun
itself makes it terminate the job, so under mpirun prefer SIGUSR1 (Slurm's srun and
most schedulers deliver SIGTERM to every task directly).
"""
from __future__ import annotations

import signal
import threading

import numpy as np
from mpi4py import MPI

DEFAULT_SIGNALS = (signal.SIGTERM, signal.SIGUSR1)
STOP_CHECK_EVERY = 100  # steps between collective checks, a suggestion for the step loop


class StopRequest:
    """Flag set by SIGTERM/SIGUSR1 (or `request()`); `should_stop(comm)` agrees on it over ranks."""

    def __init__(self, signals=DEFAULT_SIGNALS, install: bool = True):
        self.signals = tuple(signals)
        self.requested = False
        self.signal_name: str | None = None
        self._previous: dict = {}
        if install:
            self.install()

    def _handler(self, signum, frame):  # noqa: ARG002 - signal handler signature
        self.requested = True
        self.signal_name = signal.Signals(signum).name

    def install(self) -> None:
        """Install the handlers (main thread only; elsewhere this is a no-op)."""
        if threading.current_thread() is not threading.main_thread():
            return
        for signum in self.signals:
            if signum not in self._previous:
                self._previous[signum] = signal.signal(signum, self._handler)

    def restore(self) -> None:
        """Put back the handlers that were installed before."""
        for signum, previous in self._previous.items():
            signal.signal(signum, previous if previous is not None else signal.SIG_DFL)
        self._previous.clear()

    def request(self, reason: str = "requested") -> None:
        """Ask for a stop from code (e.g. a wall-clock budget)."""
        self.requested = True
        self.signal_name = reason

    def should_stop(self, comm) -> bool:
        """True on every rank if any rank was asked to stop (collective: call on all ranks)."""
        flag = np.array([1 if self.requested else 0], dtype=np.int32)
        comm.Allreduce(MPI.IN_PLACE, flag, op=MPI.MAX)
        return bool(flag[0])

    def __enter__(self):
        self.install()
        return self

    def __exit__(self, *exc):
        self.restore()
        return False

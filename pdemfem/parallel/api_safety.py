"""The Python API under MPI: pdemfem's messages never meet the user's, and an error on some
ranks never leaves the others waiting.

    self.comm, self.error_comm = private_communicators(user_comm)
    @collective_errors                      # on the Simulation's public methods
    def run(self): ...

* `private_communicators` duplicates the user's communicator (once per communicator, reused by
  later Simulations): pdemfem's collectives and its fixed point-to-point tags (ghost exchange)
  live in their own communication context, so they cannot match a message the user's code has
  in flight on its communicator, whatever its tag.
* `collective_errors`: when a public method raises on a rank, that rank waits on a barrier of a
  communicator used for nothing else.  If every rank fails (the usual case: a scene error is seen
  by all), the barrier completes and each re-raises its error.  If the others do not fail within
  PDEMFEM_ERROR_SYNC_SECONDS (30 s) -- they wait in a collective the failing rank will never
  join -- the failing rank prints the error with its rank and aborts the job with the error's
  exit code, so no rank hangs (the CLI does the same for the whole command).
* `abort_on_uncaught_exceptions`: installed when a Simulation is made on several ranks.  An exception that
  ends a user's script on one rank (a typo in one rank's branch, a failing local query such as
  `wall_force("flor")`) aborts the job after its traceback is printed.  Without it the rank would reach
  MPI's finalisation, which waits for the others, while they wait in the next collective step: the job
  hung until the batch system killed it.  A hook the user installed is left alone.
"""
from __future__ import annotations

import functools
import os
import sys
import time
import traceback

_PRIVATE = []  # (user communicator, (work duplicate, error duplicate))


def _sync_seconds() -> float:
    return float(os.environ.get("PDEMFEM_ERROR_SYNC_SECONDS", "30"))


def private_communicators(comm):
    """(work, error) duplicates of `comm` (collective on first use for this communicator)."""
    from mpi4py import MPI

    for user, duplicates in _PRIVATE:
        if user == comm and MPI.Group.Compare(user.Get_group(), comm.Get_group()) == MPI.IDENT:
            return duplicates
    duplicates = (comm.Dup(), comm.Dup())
    _PRIVATE.append((comm, duplicates))
    return duplicates


def collective_errors(method):
    """Decorator for a public method of an object with `error_comm` (see the module docstring)."""
    @functools.wraps(method)
    def guarded(self, *args, **kwargs):
        depth = getattr(self, "_api_call_depth", 0)
        self._api_call_depth = depth + 1
        try:
            return method(self, *args, **kwargs)
        except Exception as error:
            if depth == 0:  # only the outermost public call agrees (run() calls write_checkpoint())
                agree_or_abort(getattr(self, "error_comm", None), error)
            raise
        finally:
            self._api_call_depth = depth
    return guarded


def agree_or_abort(comm, error: BaseException) -> None:
    """Return when every rank of `comm` failed too; else print the error and abort the job."""
    if comm is None or comm.size == 1:
        return
    request = comm.Ibarrier()
    deadline = time.monotonic() + _sync_seconds()
    while not request.Test():
        if time.monotonic() > deadline:
            from pdemfem.errors import PdemfemError

            code = getattr(error, "exit_code", 1) if isinstance(error, PdemfemError) else 1
            text = str(error) if isinstance(error, PdemfemError) else traceback.format_exc()
            sys.stdout.flush()
            sys.stderr.write(f"error: (rank {comm.rank} of {comm.size}; the other ranks did not fail with it, "
                             f"aborting so that none waits forever) {text}\n")
            sys.stderr.flush()
            comm.Abort(code)
        time.sleep(0.002)


def abort_on_uncaught_exceptions(comm) -> None:
    """Make an uncaught exception on one rank abort the whole job (see the module docstring); nothing on one
    rank, or when sys.excepthook is not Python's own."""
    if comm is None or comm.size == 1 or sys.excepthook is not sys.__excepthook__:
        return

    def abort(kind, value, trace):
        from mpi4py import MPI

        from pdemfem.errors import PdemfemError

        sys.__excepthook__(kind, value, trace)
        code = getattr(value, "exit_code", 1) if isinstance(value, PdemfemError) else 1
        sys.stdout.flush()
        sys.stderr.write(f"error: (rank {MPI.COMM_WORLD.rank} of {MPI.COMM_WORLD.size}) the exception above ended "
                         f"this rank: aborting the job so that the other ranks do not wait for it forever\n")
        sys.stderr.flush()
        MPI.COMM_WORLD.Abort(code)

    sys.excepthook = abort

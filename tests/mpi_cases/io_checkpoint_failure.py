"""MPI case: a checkpoint write that fails on one rank only fails on every rank alike
(tests/test_io_checkpoint.py).

usage: io_checkpoint_failure.py DIR layout|rows
layout: rank 0's HDF5 layout of the file fails (the other ranks wait for its offsets);
rows: rank 1's pwrite of its rows fails (the others go on sorting and writing theirs).
Each rank prints "rank R: <CheckpointError problem>"; the checkpoint written before stays
readable and the temporary file is gone.
"""
import errno
import sys
from pathlib import Path

import numpy as np

import pdemfem  # noqa: F401  (environment first)
from mpi4py import MPI

from pdemfem.errors import CheckpointError
from pdemfem.io import checkpoint as ckpt


def arrays(comm, n=200):
    rng = np.random.default_rng(comm.rank)
    ids = rng.permutation(np.arange(comm.rank, n, comm.size, dtype=np.int64))  # interleaved: rows move
    return {"ids": ids, "positions": rng.random((len(ids), 3))}


def say(line: str) -> None:
    """One write per line: two ranks share the pipe, and print() writes the text and its newline apart
    (under load another rank's line landed between them)."""
    sys.stdout.write(line + "\n")
    sys.stdout.flush()


def main():
    folder, where = Path(sys.argv[1]), sys.argv[2]
    comm = MPI.COMM_WORLD
    good = ckpt.write_checkpoint(ckpt.checkpoint_path(folder, 1), comm, arrays(comm), attributes={"step": 1})

    def full_disk(*args, **kwargs):
        raise OSError(errno.ENOSPC, "No space left on device")

    if where == "layout" and comm.rank == 0:
        ckpt._create_layout = full_disk
    if where == "rows" and comm.rank == 1:
        ckpt._write_at = full_disk
    try:
        ckpt.write_checkpoint(ckpt.checkpoint_path(folder, 2), comm, arrays(comm), attributes={"step": 2})
        say(f"rank {comm.rank}: no error")
    except CheckpointError as error:
        say(f"rank {comm.rank}: {error.problem}")
    comm.Barrier()
    if comm.rank == 0:
        left = sorted(path.name for path in folder.iterdir())
        say(f"files: {' '.join(left)}")
    checkpoint = ckpt.read_checkpoint(good, comm)
    total = comm.allreduce(len(checkpoint.particles["ids"]))
    if comm.rank == 0:
        say(f"previous checkpoint readable: {total} particles")


if __name__ == "__main__":
    main()

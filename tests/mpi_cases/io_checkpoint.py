"""MPI case: write checkpoints from rank-local data, read them back on any rank count.

    io_checkpoint.py write DIR N_PARTICLES STEP [STEP ...]   # one checkpoint per STEP, keep=2
    io_checkpoint.py read FILE N_PARTICLES STEP              # check this rank's share, print OK
    io_checkpoint.py loop DIR N_PARTICLES                    # write forever (for the SIGKILL test)

Particle values are particles_for(ids, step) with unsorted, unevenly split
ids; contacts, globals and slabs are functions of ids / rows and step too.
"""
import json
import sys
from pathlib import Path

import numpy as np

sys.path.insert(0, str(Path(__file__).parent))
import pdemfem  # noqa: E402,F401
from mpi4py import MPI  # noqa: E402

import io_data  # noqa: E402
from pdemfem.io.checkpoint import FORMAT_VERSION, checkpoint_path, read_checkpoint, write_checkpoint  # noqa: E402

comm = MPI.COMM_WORLD
SLAB_ROWS = 1001


def particles_for(ids: np.ndarray, step: int) -> dict:
    """io_data.particle_arrays and a 4-byte integer field, as the solver's material index: its checksum must
    not depend on how the rows are split over the writing and the reading ranks (unevenly, odd counts)."""
    arrays = io_data.particle_arrays(ids, step)
    arrays["material_index"] = ((np.asarray(ids) + step) % 5).astype(np.int32)
    return arrays


def contacts_for(ids: np.ndarray, count: int, step: int) -> dict:
    partners = (ids * 7 + 3 + step) % count
    pairs = np.column_stack([ids, partners]).astype(np.int64)
    return {"pairs": pairs, "shear": np.column_stack([pairs[:, 0] * 1e-9, pairs[:, 1] * 1e-9, pairs.sum(1) + step * 0.5])}


def slab_for(first: int, stop: int, step: int) -> np.ndarray:
    rows = np.arange(first, stop, dtype=np.float64)
    return np.column_stack([rows, rows * 0.5 + step, -rows])


def globals_for(step: int) -> dict:
    return {"wall_positions": np.array([[0.0, 0.0, step * 1e-3], [1.0, 2.0, 3.0]]),
            "insertion_counts": np.array([step, 2 * step], dtype=np.int64)}


def attributes_for(step: int) -> dict:
    return {"step": step, "time": step * 1.0e-5, "scene_hash": "abc123",
            "rng_state": json.dumps({"bit_generator": "PCG64", "state": {"state": 12345 + step, "inc": 7}}),
            "insertion": {"inserted": step * 3, "next_time": 0.25}}


def write(directory: Path, count: int, step: int):
    ids = io_data.rank_particle_ids(count, comm.rank, comm.size, step)
    first, stop = SLAB_ROWS * comm.rank // comm.size, SLAB_ROWS * (comm.rank + 1) // comm.size
    write_checkpoint(checkpoint_path(directory, step), comm, particles_for(ids, step),
                     global_arrays=globals_for(step), attributes=attributes_for(step),
                     slab_arrays={"u": (slab_for(first, stop, step), first)},
                     contact_arrays=contacts_for(ids, count, step), keep=2)


mode, target, count = sys.argv[1], Path(sys.argv[2]), int(sys.argv[3])
if mode == "write":
    for step in map(int, sys.argv[4:]):
        write(target, count, step)
elif mode == "loop":
    step = 0
    while True:
        write(target, count, step)
        step += 1
elif mode == "read":
    step = int(sys.argv[4])
    checkpoint = read_checkpoint(target, comm, expected_hash="abc123")
    first, stop = count * comm.rank // comm.size, count * (comm.rank + 1) // comm.size
    assert checkpoint.particle_count == count and checkpoint.particle_rows == (first, stop)
    ids = np.arange(first, stop, dtype=np.int64)
    for name, values in particles_for(ids, step).items():
        assert np.array_equal(checkpoint.particles[name], values), name
    attributes = checkpoint.attributes
    for name, value in attributes_for(step).items():
        assert attributes[name] == value, (name, attributes[name], value)
    assert attributes["format_version"] == FORMAT_VERSION
    for name, value in globals_for(step).items():
        assert np.array_equal(checkpoint.globals[name], value), name
    assert np.array_equal(checkpoint.slabs["u"], slab_for(0, SLAB_ROWS, step))
    # contacts: gather the shares, compare with all contacts sorted by pair
    pairs = np.concatenate(comm.allgather(checkpoint.contacts["pairs"]))
    shear = np.concatenate(comm.allgather(checkpoint.contacts["shear"]))
    expected = contacts_for(np.arange(count, dtype=np.int64), count, step)
    order = np.lexsort(expected["pairs"].T[::-1])
    assert np.array_equal(pairs, expected["pairs"][order])
    assert np.array_equal(shear, expected["shear"][order])
    if comm.rank == 0:
        print("OK", comm.size)

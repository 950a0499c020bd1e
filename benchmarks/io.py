"""I/O bandwidth: particle output, solid output and checkpoints vs the raw file write speed.

    .venv/bin/python benchmarks/io.py [--particles 1000000] [--dofs 1000000] [--ranks 1 2] [--dir DIR]
    .venv/bin/python benchmarks/io.py --only checkpoint --repeat 7

For each rank count the script runs itself under mpiexec (``--worker``): 1M particles
split evenly (unsorted ids), written as one particle output step (positions, velocities,
radii, ids, forces, temperature) and as a checkpoint (those plus angular velocities and
two FE vectors); and a solid of ~1M DOF (box tet mesh, mesh + displacements, velocities,
temperature, von Mises per step).  The raw reference writes the same number of bytes
with plain write() calls in 8 MiB blocks ("dd bs=8M"): appended to one growing file
without fsync (what the output streams do: compare output with it), and as a new file
with fsync (what a checkpoint does: compare checkpoints with it).  Median (and best) of --repeat runs.
A checkpoint is timed from the call to write_checkpoint to its return on every rank (id sort,
write, fsync, rename, directory fsync); the process's first checkpoint (loading the sort kernels
from numba's cache) and the deletion of the previous checkpoint (an unlink, as the raw
reference's) are not timed.  --only checkpoint (or output) measures one part.  Table on stdout,
JSON to benchmarks/results/io.json.
"""
from __future__ import annotations

import argparse
import json
import os
import subprocess
import sys
import tempfile
import time
from pathlib import Path

import numpy as np

sys.path.insert(0, str(Path(__file__).resolve().parents[1]))
import pdemfem  # noqa: E402,F401

RESULTS = Path(__file__).parent / "results" / "io.json"


def raw_write(path: Path, nbytes: int, fsync: bool) -> float:
    """Seconds to write `nbytes`: appended to `path` (a growing file, like an output stream)
    without fsync, or as a new file with fsync (like a checkpoint)."""
    block = np.random.default_rng(0).integers(0, 255, size=8 << 20, dtype=np.uint8).tobytes()
    started = time.perf_counter()
    with open(path, "wb" if fsync else "ab") as handle:
        left = nbytes
        while left > 0:
            handle.write(block[: min(left, len(block))])
            left -= len(block)
        handle.flush()
        if fsync:
            os.fsync(handle.fileno())
    elapsed = time.perf_counter() - started
    if fsync:
        path.unlink()
    return elapsed


def box_mesh(n: int):
    """(n+1)^3 nodes, 6 n^3 tets (Kuhn split), nodes numbered x-fastest."""
    g = np.arange(n + 1)
    Z, Y, X = np.meshgrid(g, g, g, indexing="ij")
    points = np.column_stack([X.ravel(), Y.ravel(), Z.ravel()]).astype(np.float64) / n
    i, j, k = np.meshgrid(np.arange(n), np.arange(n), np.arange(n), indexing="ij")
    base = ((k * (n + 1) + j) * (n + 1) + i).ravel()
    offsets = [0, 1, n + 1, n + 2, (n + 1) ** 2, (n + 1) ** 2 + 1, (n + 1) ** 2 + n + 1, (n + 1) ** 2 + n + 2]
    corners = base[:, None] + np.array(offsets)[None, :]
    kuhn = [(0, 1, 3, 7), (0, 1, 5, 7), (0, 2, 3, 7), (0, 2, 6, 7), (0, 4, 5, 7), (0, 4, 6, 7)]
    cells = np.concatenate([corners[:, list(t)] for t in kuhn])
    return points, cells


def worker(args) -> None:
    from mpi4py import MPI

    from pdemfem.io.checkpoint import checkpoint_path, write_checkpoint
    from pdemfem.io.particle_output import ParticleOutput
    from pdemfem.io.solid_output import SolidOutput

    comm = MPI.COMM_WORLD
    out = Path(args.dir)
    n = args.particles
    first, stop = n * comm.rank // comm.size, n * (comm.rank + 1) // comm.size
    rng = np.random.default_rng(comm.rank)
    ids = rng.permutation(np.arange(first, stop, dtype=np.int64))
    owned = stop - first
    particles = {"positions": rng.random((owned, 3)), "velocities": rng.random((owned, 3)),
                 "radii": rng.random(owned), "ids": ids, "forces": rng.random((owned, 3)),
                 "temperature": rng.random(owned)}
    output_bytes = sum(a.nbytes for a in particles.values())

    raw_dir = out / "raw"
    raw_dir.mkdir(parents=True, exist_ok=True)

    def timed(function, local_bytes: int, fsync: bool, prepare=None):
        """Median and best seconds of `function`, each run followed by a raw write of the
        same bytes (every rank writes its own share to its own file), so both see the
        same page-cache and disk state.  `prepare` runs before each timed call, untimed."""
        ours, raw = [], []
        for _ in range(args.repeat):
            if prepare is not None:
                prepare()
            comm.Barrier()
            started = time.perf_counter()
            function()
            comm.Barrier()
            ours.append(time.perf_counter() - started)
            comm.Barrier()
            started = time.perf_counter()
            raw_write(raw_dir / f"{'new' if fsync else 'append'}.{comm.rank}", local_bytes, fsync)
            comm.Barrier()
            raw.append(time.perf_counter() - started)
        return {"seconds": float(np.median(ours)), "best": min(ours),
                "raw_seconds": float(np.median(raw)), "raw_best": min(raw)}

    measured = {}
    counter = iter(range(10**6))
    if args.only in ("all", "output"):
        writer = ParticleOutput(out / "output", comm)
        measured["particle_output"] = (output_bytes, timed(lambda: writer.write(0.0, next(counter), particles),
                                                           output_bytes, False))

    dof_nodes = args.dofs // 3
    cube = max(2, round(dof_nodes ** (1.0 / 3.0)) - 1)
    nodes = (cube + 1) ** 3
    node_first, node_stop = nodes * comm.rank // comm.size, nodes * (comm.rank + 1) // comm.size
    if args.only in ("all", "output"):
        points, cells = box_mesh(cube)
        cell_owner = np.searchsorted([nodes * r // comm.size for r in range(1, comm.size)], cells[:, 0], side="right")
        owned_cells = cells[cell_owner == comm.rank]
        owned_points = points[node_first:node_stop]
        del points, cells
        point_data = {"displacements": rng.random((len(owned_points), 3)),
                      "velocities": rng.random((len(owned_points), 3)), "temperature": rng.random(len(owned_points))}
        cell_data = {"von_mises": rng.random(len(owned_cells))}
        solid_step_bytes = sum(a.nbytes for a in point_data.values()) + sum(a.nbytes for a in cell_data.values())
        solid_mesh_bytes = owned_points.nbytes + owned_cells.nbytes
        measured["solid_mesh"] = (solid_mesh_bytes, timed(
            lambda: SolidOutput(out / "output", "solid", comm, owned_points, owned_cells, node_first),
            solid_mesh_bytes, False))
        solid = SolidOutput(out / "output", "solid", comm, owned_points, owned_cells, node_first)
        measured["solid_step"] = (solid_step_bytes, timed(lambda: solid.write(0.0, next(counter), point_data, cell_data),
                                                          solid_step_bytes, False))

    if args.only in ("all", "checkpoint"):
        state = dict(particles, angular_velocities=rng.random((owned, 3)))
        owned_nodes = node_stop - node_first
        slabs = {"u": (rng.random(3 * owned_nodes), 3 * node_first), "u_prev": (rng.random(3 * owned_nodes), 3 * node_first)}
        checkpoint_bytes = sum(a.nbytes for a in state.values()) + sum(a.nbytes for a, _ in slabs.values())
        written = []

        def remove_previous():
            """A run with checkpoint.keep deletes the previous checkpoint after writing the new one: an
            unlink (30-60 ms for 136 MB here), not a write; like the raw reference's unlink, untimed."""
            if comm.rank == 0:
                for path in written:
                    path.unlink(missing_ok=True)
            written.clear()

        def checkpoint():
            # Sort by id, write, fsync, rename, directory fsync.
            written.append(write_checkpoint(checkpoint_path(out / "checkpoints", next(counter)), comm, state,
                                            slab_arrays=slabs, attributes={"step": 0}))

        checkpoint()  # the first call of a process loads the sort kernels from numba's cache: untimed
        measured["checkpoint"] = (checkpoint_bytes, timed(checkpoint, checkpoint_bytes, True, prepare=remove_previous))
        remove_previous()
    finish(comm, args, nodes, measured)


def finish(comm, args, nodes: int, measured: dict) -> None:
    """Sum the bytes over the ranks; rank 0 writes the worker's result file."""
    from mpi4py import MPI

    names = list(measured)
    totals = np.array([measured[name][0] for name in names], dtype=np.int64)
    comm.Allreduce(MPI.IN_PLACE, totals, op=MPI.SUM)
    if comm.rank == 0:
        result = {"ranks": comm.size, "particles": args.particles, "solid_nodes": nodes, "solid_dofs": 3 * nodes}
        for name, total in zip(names, totals):
            result[name] = dict(bytes=int(total), **measured[name][1])
        Path(args.result).write_text(json.dumps(result))


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--particles", type=int, default=1_000_000)
    parser.add_argument("--dofs", type=int, default=1_000_000)
    parser.add_argument("--ranks", type=int, nargs="+", default=[1, 2])
    parser.add_argument("--repeat", type=int, default=5)
    parser.add_argument("--only", choices=("all", "output", "checkpoint"), default="all",
                        help="measure only the output streams or only checkpoints")
    parser.add_argument("--dir", default=None, help="where to write (default: a temporary directory under .)")
    parser.add_argument("--worker", action="store_true", help=argparse.SUPPRESS)
    parser.add_argument("--result", help=argparse.SUPPRESS)
    args = parser.parse_args()
    if args.worker:
        worker(args)
        return

    from pdemfem.runtime import mpiexec_command, process_environment

    base = Path(args.dir) if args.dir else Path(tempfile.mkdtemp(prefix="io-bench-", dir="."))
    base.mkdir(parents=True, exist_ok=True)
    runs = []
    for ranks in args.ranks:
        directory = base / f"ranks{ranks}"
        result_file = base / f"result{ranks}.json"
        command = mpiexec_command(ranks, [sys.executable, __file__, "--worker", "--dir", str(directory),
                                          "--result", str(result_file), "--particles", str(args.particles),
                                          "--dofs", str(args.dofs), "--repeat", str(args.repeat),
                                          "--only", args.only])
        subprocess.run(command, env=process_environment(), check=True)
        runs.append(json.loads(result_file.read_text()))

    rows = []
    print(f"{'what':<16}{'ranks':>6}{'MB':>8}{'s':>8}{'MB/s':>8}{'raw MB/s':>10}{'ratio':>7}"
          f"{'best MB/s':>11}{'raw best':>10}  raw reference")
    for run in runs:
        for key, reference in (("particle_output", "append, no fsync"), ("solid_mesh", "append, no fsync"),
                               ("solid_step", "append, no fsync"), ("checkpoint", "new file + fsync")):
            if key not in run:
                continue
            entry = run[key]
            nbytes = entry["bytes"]
            row = {"what": key, "ranks": run["ranks"], "bytes": nbytes, "seconds_median": entry["seconds"],
                   "MB_per_s": nbytes / entry["seconds"] / 1e6, "raw_MB_per_s": nbytes / entry["raw_seconds"] / 1e6,
                   "fraction_of_raw": entry["raw_seconds"] / entry["seconds"],
                   "best_MB_per_s": nbytes / entry["best"] / 1e6, "raw_best_MB_per_s": nbytes / entry["raw_best"] / 1e6,
                   "raw_reference": f"write() 8 MiB blocks, {reference}, each rank its share"}
            rows.append(row)
            print(f"{key:<16}{run['ranks']:>6}{nbytes / 1e6:>8.1f}{entry['seconds']:>8.3f}{row['MB_per_s']:>8.0f}"
                  f"{row['raw_MB_per_s']:>10.0f}{row['fraction_of_raw']:>7.2f}{row['best_MB_per_s']:>11.0f}"
                  f"{row['raw_best_MB_per_s']:>10.0f}  {reference}")
    RESULTS.parent.mkdir(parents=True, exist_ok=True)
    RESULTS.write_text(json.dumps({"particles": args.particles, "solid_dofs": runs[0]["solid_dofs"],
                                   "repeat": args.repeat, "statistic": "median (best also given)",
                                   "runs": runs, "table": rows}, indent=1))
    print(f"wrote {RESULTS}")
    if not args.dir:
        import shutil

        shutil.rmtree(base)


if __name__ == "__main__":
    main()

"""Benchmark of one solid: assembly, static solve, MatMult versus one explicit step.

    .venv/bin/python benchmarks/fem_step.py --cells 40 40 40
    .venv/bin/python -m pdemfem.launch -n 2 -- .venv/bin/python benchmarks/fem_step.py

Prints a table (rank 0) and writes JSON (--json, default benchmarks/results/fem_step_<ranks>.json).
A box of 40^3 hexahedra (6 tetrahedra each) is ~207k DOF with P1.
"""
from __future__ import annotations

import argparse
import json
import resource
import time
from pathlib import Path



def main(argv=None):
    import pdemfem  # noqa: F401
    from mpi4py import MPI

    from pdemfem.fem import Solid, SolidConfig
    from pdemfem.scene.schema import MaterialConfig

    parser = argparse.ArgumentParser(description=__doc__)
    parser.add_argument("--cells", type=int, nargs=3, default=[40, 40, 40])
    parser.add_argument("--element", default="P1")
    parser.add_argument("--mass", default="lumped")
    parser.add_argument("--steps", type=int, default=200)
    parser.add_argument("--json", default=None, help="result file (default benchmarks/results/fem_step_<ranks>.json)")
    args = parser.parse_args(argv)
    comm = MPI.COMM_WORLD

    config = SolidConfig(name="bench", mesh={"box": [[0, 0, 0], [1, 1, 1]], "cells": args.cells}, material="steel",
                         element=args.element, mass=args.mass, fixed=["zmin"])
    steel = MaterialConfig(density=7800.0, youngs_modulus=2e11, poisson_ratio=0.3)
    comm.Barrier()
    start = time.perf_counter()
    solid = Solid(config, steel, comm=comm)
    comm.Barrier()
    setup = time.perf_counter() - start
    start = time.perf_counter()
    result = solid.static_solve()
    comm.Barrier()
    static = time.perf_counter() - start

    x = solid.displacement_vec.duplicate()
    y = x.duplicate()
    x.setRandom()
    solid.stiffness.mult(x, y)  # warm-up
    comm.Barrier()
    start = time.perf_counter()
    for _ in range(args.steps):
        solid.stiffness.mult(x, y)
    comm.Barrier()
    matmult = (time.perf_counter() - start) / args.steps
    dt = solid.critical_time_step()
    solid.step(dt)  # warm-up
    comm.Barrier()
    start = time.perf_counter()
    for _ in range(args.steps):
        solid.step(dt)
    comm.Barrier()
    step = (time.perf_counter() - start) / args.steps

    dofs = 3 * solid.n_global_nodes
    from petsc4py import PETSc

    info = solid.stiffness.getInfo(PETSc.Mat.InfoType.LOCAL)  # this rank's part; summed below
    matrix_mb = comm.allreduce(info["nz_used"]) * 8 / 1e6  # values only (BAIJ: one index per 3x3 block)
    peak_mb = comm.allreduce(resource.getrusage(resource.RUSAGE_SELF).ru_maxrss) / 1e3
    if comm.rank == 0:
        rows = [
            ("ranks", f"{comm.size}"),
            ("element / mass", f"{args.element} / {args.mass}"),
            ("DOF", f"{dofs}"),
            ("cells", f"{solid.mesh.n_global_cells}"),
            ("setup (mesh, partition, assembly) [s]", f"{setup:.2f}"),
            ("static solve [s] / iterations", f"{static:.2f} / {result.iterations}"),
            ("MatMult K [ms]", f"{1e3 * matmult:.2f}"),
            ("explicit step [ms]", f"{1e3 * step:.2f}"),
            ("step / MatMult", f"{step / matmult:.2f}"),
            ("step [ns per DOF]", f"{1e9 * step / dofs:.1f}"),
            ("critical step [s]", f"{dt:.3e}"),
            ("K values [MB]", f"{matrix_mb:.1f}"),
            ("peak RSS, all ranks [MB]", f"{peak_mb:.0f}"),
        ]
        width = max(len(name) for name, _ in rows)
        for name, value in rows:
            print(f"{name:<{width}}  {value}")
        results = {"ranks": comm.size, "element": args.element, "mass": args.mass, "dofs": dofs,
                   "cells": int(solid.mesh.n_global_cells), "setup_seconds": setup, "static_seconds": static,
                   "static_iterations": int(result.iterations), "matmult_seconds": matmult, "step_seconds": step,
                   "step_over_matmult": step / matmult, "step_ns_per_dof": 1e9 * step / dofs,
                   "critical_step": dt, "matrix_megabytes": matrix_mb, "peak_rss_megabytes": peak_mb}
        path = Path(args.json or Path(__file__).parent / "results" / f"fem_step_{comm.size}.json")
        path.parent.mkdir(parents=True, exist_ok=True)
        path.write_text(json.dumps(results, indent=2))
        print(f"wrote {path}")
    return 0


if __name__ == "__main__":
    raise SystemExit(main())

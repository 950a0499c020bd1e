"""Benchmark of heat conduction in a solid: explicit versus implicit, cost per advance and accuracy.

    .venv/bin/python benchmarks/solid_heat.py
    .venv/bin/python benchmarks/solid_heat.py --cells 10 20 --interval 1e-5 --repeats 200

Part 1 (cost): a 0.1 m cube of steel and of rubber (k, rho c below), box meshes of n^3 hexahedra (6 P1
tetrahedra each).  Per material and mesh: the explicit heat limit, the mechanics' critical step, and the
wall time of one heat advance over a DEM-sized interval (explicit, implicit backward Euler, Crank-Nicolson),
of the thermal-load refresh an advance adds with thermal expansion, and of the mechanical advance itself.
Part 2 (accuracy): the bar of tests/fem/test_fem_heat.py (diffusivity 1, 16 cubic cells, held end) at
t = 0.2 against its Fourier series, for advance intervals of 0.5 to 100 explicit limits.

Prints tables (rank 0) and writes JSON (--json, default benchmarks/results/solid_heat.json).
"""
from __future__ import annotations

import argparse
import json
import time
from pathlib import Path

import numpy as np

MATERIALS = {  # density [kg/m^3], E [Pa], nu, conductivity [W/(m K)], specific heat [J/(kg K)], alpha [1/K]
    "steel": dict(density=7800.0, youngs_modulus=2e11, poisson_ratio=0.3, conductivity=50.0, heat_capacity=490.0,
                  thermal_expansion=1.2e-5),
    "rubber": dict(density=1100.0, youngs_modulus=5e6, poisson_ratio=0.45, conductivity=0.15, heat_capacity=2000.0,
                   thermal_expansion=2e-4),
}


def timed(function, repeats: int, batches: int = 5) -> float:
    """Mean time of one call: the fastest of `batches` batches (the machine is shared: the other batches
    carry other jobs' load)."""
    function()  # warm-up (numba, solver set-up)
    best = float("inf")
    for _ in range(batches):
        start = time.perf_counter()
        for _ in range(repeats):
            function()
        best = min(best, (time.perf_counter() - start) / repeats)
    return best


def cost_rows(cells_list, interval: float, repeats: int) -> list:
    from pdemfem.fem import Solid, SolidConfig
    from pdemfem.scene.schema import MaterialConfig

    rows = []
    for name, values in MATERIALS.items():
        material = MaterialConfig(**values)
        for cells in cells_list:
            row = {"material": name, "cells": cells, "h": 0.1 / cells}
            for scheme, theta in (("explicit", 1.0), ("implicit", 1.0), ("implicit", 0.5)):
                config = SolidConfig(name="cube", mesh={"box": [[0, 0, 0], [0.1, 0.1, 0.1]], "cells": [cells] * 3},
                                     material=name, fixed=["zmin"], initial_temperature=300.0,
                                     reference_temperature=300.0,
                                     thermal={"scheme": scheme, "theta": theta,
                                              "fixed": [{"group": "zmin", "temperature": 350.0}],
                                              "convection": [{"group": "zmax", "coefficient": 20.0, "ambient": 290.0}]})
                solid = Solid(config, material, gravity=(0.0, 0.0, 0.0))
                label = scheme if scheme == "explicit" else f"implicit_theta{theta:g}"
                row["nodes"] = solid.n_global_nodes
                row["heat_limit_s"] = solid.heat_critical_time_step()
                row["mechanical_limit_s"] = solid.critical_time_step()
                row[f"{label}_heat_advance_s"] = timed(lambda: solid.heat.advance(interval), repeats)
                if scheme == "implicit" and theta == 1.0:
                    row["implicit_iterations"] = solid.heat._solver.getIterationNumber()
                    row["implicit_pc"] = solid.heat._solver.getPC().getType()
                if scheme == "explicit":
                    row["thermal_load_refresh_s"] = timed(solid._refresh_thermal_load, repeats)
                    row["mechanical_advance_s"] = timed(lambda: _mechanical_advance(solid, interval), repeats)
            rows.append(row)
    return rows


def _mechanical_advance(solid, interval):
    """Solid.advance without its heat part: the sub-cycled central-difference steps alone."""
    heat, solid.heat = solid.heat, None
    try:
        solid.advance(interval)
    finally:
        solid.heat = heat


def accuracy_rows(multiples) -> list:
    import sys

    tests = Path(__file__).resolve().parent.parent / "tests"
    sys.path[:0] = [str(tests), str(tests / "fem")]  # the bar and its series from the test (one copy)
    from test_fem_heat import T0, T1, bar, fourier_series

    rows = []
    for multiple in multiples:
        row = {"interval_in_limits": multiple}
        for scheme, theta in (("explicit", 1.0), ("implicit", 1.0), ("implicit", 0.5)):
            solid = bar(16, {"scheme": scheme, "theta": theta})
            interval = multiple * solid.heat_critical_time_step()
            advances = max(1, int(round(0.2 / interval)))
            interval = 0.2 / advances
            start = time.perf_counter()
            steps = sum(solid.heat.advance(interval) for _ in range(advances))
            elapsed = time.perf_counter() - start
            x = solid.reference_positions[:, 0]
            label = scheme if scheme == "explicit" else f"implicit_theta{theta:g}"
            row[f"{label}_max_error"] = float(np.abs(solid.temperatures - fourier_series(x, 0.2)).max() / (T1 - T0))
            row[f"{label}_steps"] = steps
            row[f"{label}_time_s"] = elapsed
        rows.append(row)
    return rows


def main(argv=None):
    import pdemfem  # noqa: F401
    from mpi4py import MPI

    parser = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    parser.add_argument("--cells", type=int, nargs="+", default=[10, 20], help="hexahedra per side of the cube")
    parser.add_argument("--interval", type=float, default=1e-5, help="advance interval [s] (a DEM-sized step)")
    parser.add_argument("--repeats", type=int, default=200)
    parser.add_argument("--multiples", type=float, nargs="+", default=[0.5, 2.0, 20.0, 100.0],
                        help="advance intervals of the accuracy table, in explicit limits")
    parser.add_argument("--json", default=None, help="result file (default benchmarks/results/solid_heat.json)")
    args = parser.parse_args(argv)
    comm = MPI.COMM_WORLD

    costs = cost_rows(args.cells, args.interval, args.repeats)
    accuracy = accuracy_rows(args.multiples) if comm.size == 1 else []
    if comm.rank:
        return
    print(f"Cost of one advance over {args.interval:g} s (0.1 m cube, P1, {comm.size} rank(s)); times in microseconds")
    print(f"{'material':8} {'cells':>5} {'nodes':>6} {'heat limit s':>12} {'mech limit s':>12} {'explicit':>9} "
          f"{'BE':>9} {'CN':>9} {'BE its':>6} {'load refresh':>12} {'mech advance':>12}")
    for row in costs:
        print(f"{row['material']:8} {row['cells']:5d} {row['nodes']:6d} {row['heat_limit_s']:12.3e} "
              f"{row['mechanical_limit_s']:12.3e} {1e6 * row['explicit_heat_advance_s']:9.1f} "
              f"{1e6 * row['implicit_theta1_heat_advance_s']:9.1f} {1e6 * row['implicit_theta0.5_heat_advance_s']:9.1f} "
              f"{row['implicit_iterations']:6d} {1e6 * row['thermal_load_refresh_s']:12.1f} "
              f"{1e6 * row['mechanical_advance_s']:12.1f}")
    if accuracy:
        print("\nBar (16 cells, held end) at t = 0.2: max nodal error / (T1 - T0), steps, wall time")
        print(f"{'interval/limit':>14} {'explicit':>22} {'backward Euler':>22} {'Crank-Nicolson':>22}")
        for row in accuracy:
            cells = [f"{row[f'{k}_max_error']:.2e} {row[f'{k}_steps']:4d} {1e3 * row[f'{k}_time_s']:6.1f}ms"
                     for k in ("explicit", "implicit_theta1", "implicit_theta0.5")]
            print(f"{row['interval_in_limits']:14g} " + " ".join(f"{c:>22}" for c in cells))
    path = Path(args.json) if args.json else Path(__file__).parent / "results" / "solid_heat.json"
    path.parent.mkdir(parents=True, exist_ok=True)
    path.write_text(json.dumps({"ranks": comm.size, "interval": args.interval, "costs": costs, "accuracy": accuracy},
                               indent=1))
    print(f"\nwrote {path}")


if __name__ == "__main__":
    main()

"""The coupled surface's gather per FE advance: whole surface vs each rank's part (pdemfem.coupling.selection).

A 0.6 x 0.6 x 0.02 m plate clamped at x = 0 and 0.6, meshed CELLS x CELLS x 1 hexahedra -> P1 tetrahedra
(61 x 61 = 3721 surface nodes by default), with grains (r ~ 5 mm) settling onto it from a layer over the
whole plate (`--cover 1`) or over part of it (`--cover 0.5`: x < 0.3 m).  The same run is timed with the
whole gather (every rank gathers all surface nodes after every advance) and with the partial one;
the timer wraps CoupledSurface.refresh_vertices (the gather, the vertex update and, for the partial
gather, the drift test and any new selection with its whole gather) and the scatters it calls
(NodeGather.state for the whole surface, NodeGather.pair_views for a selection), per advance,
largest over the ranks.  These in-run times include the wait for the slower
rank (the scatter is where the ranks meet after the FE advance), so the script also times the two
gathers alone after the run, as the refresh calls them (displacement and velocity: the whole
surface's positions and velocities as arrays, the selection's as views of its buffers): `--repeat`
calls each, the ranks started together by a barrier, best of 5 rounds; and the same for the whole
refresh_vertices of either kind (gather, vertex update, drift test) on the run's last state.

    python -m pdemfem.launch -n 2 -- python benchmarks/partial_gather.py
    python -m pdemfem.launch -n 2 -- python benchmarks/partial_gather.py --cells 90 --cover 0.5
"""
from __future__ import annotations

import argparse
import time

import numpy as np

import pdemfem  # noqa: F401  (environment first)
from mpi4py import MPI

from pdemfem import Simulation
from pdemfem.coupling.surface import CoupledSurface
from pdemfem.fem.surface import NodeGather

from method_timers import CALLS, TIMES, wrap  # noqa: E402  (benchmarks/method_timers.py)


def scene(cells: int, cover: float, count: int) -> dict:
    side = 0.6
    return {
        "time": {"end": 1.0, "dt": 4e-5},
        "gravity": [0.0, 0.0, -9.81],
        "materials": {"grain": {"density": 2500.0, "youngs_modulus": 1e7, "poisson_ratio": 0.3},
                      "plate": {"density": 2700.0, "youngs_modulus": 7e9, "poisson_ratio": 0.33}},
        "interactions": {"default": {"model": "hertz_mindlin", "restitution": 0.3, "friction": 0.5}},
        "particles": [{"name": "grains", "material": "grain", "radius": {"min": 0.0045, "max": 0.0055},
                       "insert": {"kind": "random", "count": count, "seed": 7,
                                  "region": {"box": [[0.01, 0.01, 0.026], [cover * side - 0.01, side - 0.01, 0.05]]}}}],
        "solids": [{"name": "plate", "mesh": {"box": [[0, 0, 0], [side, side, 0.02]], "cells": [cells, cells, 1]},
                    "material": "plate", "element": "P1", "fixed": ["xmin", "xmax"], "contact": ["zmax"],
                    "damping": {"alpha": 2000.0, "beta": 0.0}}],
    }


def measure(args, partial: bool) -> dict:
    comm = MPI.COMM_WORLD
    CoupledSurface.partial_gather = partial
    sim = Simulation.from_dict(scene(args.cells, args.cover, args.count), comm=comm, output_dir="/tmp/partial_gather")
    sim.step(args.warmup)
    TIMES.clear()
    CALLS.clear()
    sim.step(args.steps)
    surface = sim.coupled_surfaces[0]
    advances = max(CALLS["refresh"], 1)
    local = np.array([TIMES["refresh"] / advances, TIMES["gather"] / advances])
    largest = np.zeros(2)
    comm.Allreduce(local, largest, op=MPI.MAX)
    gathered = len(surface.selection.rows) if surface.selection is not None else len(surface.node_indices)
    result = {"refresh": largest[0], "gather": largest[1], "gathered": comm.gather(gathered, root=0),
              "nodes": len(surface.node_indices), "selections": surface.selections, "advances": advances}
    if surface.selection is not None:
        solid = surface.solid
        selection = surface.selection
        interval = sim.dt * sim.fem_every

        def refresh(chosen):
            surface.selection = chosen  # None: the whole path (the same solid state: the timing only)
            surface.refresh_vertices(interval)
            surface.selection = selection

        gathers = {"whole": lambda: solid.contact_surface().whole.state(solid.displacement_vec, solid.velocity_vec),
                   "partial": lambda: selection.gather.pair_views(solid.displacement_vec, solid.velocity_vec),
                   "refresh whole": lambda: refresh(None), "refresh partial": lambda: refresh(selection)}
        best = {name: float("inf") for name in gathers}
        for _ in range(5):
            for name, gather in gathers.items():
                comm.Barrier()
                start = time.perf_counter()
                for _ in range(args.repeat):
                    gather()
                elapsed = np.array([(time.perf_counter() - start) / args.repeat])
                comm.Allreduce(MPI.IN_PLACE, elapsed, op=MPI.MAX)
                best[name] = min(best[name], float(elapsed[0]))
        result["alone"] = best
    return result


def main():
    parser = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    parser.add_argument("--cells", type=int, default=60)
    parser.add_argument("--cover", type=float, default=1.0, help="fraction of the plate's x extent under grains")
    parser.add_argument("--count", type=int, default=1500)
    parser.add_argument("--warmup", type=int, default=20)
    parser.add_argument("--steps", type=int, default=200)
    parser.add_argument("--repeat", type=int, default=200, help="calls per timing of a gather alone")
    args = parser.parse_args()
    wrap(CoupledSurface, "refresh_vertices", "refresh")
    wrap(NodeGather, "state", "gather")
    wrap(NodeGather, "pair_views", "gather")
    rows = [(mode, measure(args, mode == "partial")) for mode in ("whole", "partial", "whole", "partial")]
    if MPI.COMM_WORLD.rank == 0:
        print(f"{MPI.COMM_WORLD.size} ranks, {rows[0][1]['nodes']} surface nodes, {args.count} grains over "
              f"{args.cover:.0%} of the plate, {args.steps} steps (fem_every 1)")
        print(f"{'gather':8s} {'nodes per rank':>18s} {'selections':>10s} {'scatter [us]':>13s} "
              f"{'refresh [us]':>13s}")
        for mode, row in rows:
            print(f"{mode:8s} {str(row['gathered']):>18s} {row['selections']:>10d} {1e6 * row['gather']:13.1f} "
                  f"{1e6 * row['refresh']:13.1f}")
        alone = [row["alone"] for mode, row in rows if "alone" in row]
        print("the gathers alone (u and v), per advance [us], best of 5 rounds of", args.repeat, "calls:")
        for name in ("whole", "partial", "refresh whole", "refresh partial"):
            print(f"  {name:16s} " + "  ".join(f"{1e6 * times[name]:8.1f}" for times in alone))


if __name__ == "__main__":
    main()

"""Coupled DEM-FEM benchmark: a granular layer on a deformable plate; where the step time goes.

~20k spheres (r = 1.5 mm, soft glass E = 5 MPa) in three lattice layers resting on and sliding over
(initial velocity 0.1 m/s along x) a 0.3 x 0.3 x 0.02 m rubbery plate (E = 1e8) clamped at its
four sides, meshed 64 x 64 x 3 hexahedra -> P1 tetrahedra: 16,900 nodes, ~50k DOF.

    python benchmarks/coupled.py                   # 200 timed steps
    python benchmarks/coupled.py --steps 50 --cells 32 32 2
    python -m pdemfem.launch -n 2 -- python benchmarks/coupled.py

The phases are timed by wrapping the methods (wall clock, rank 0; on several ranks the FE and the
Allreduce-synchronised phases include waiting):
  search     TriangleSurface._rebuild_lists   (BVH refit + candidate lists; inside add_forces)
  contacts   TriangleSurface.add_forces minus search   (sphere-triangle kernel)
  transfer   CoupledSurface.collect_contact_forces + send_forces_to_solid (spread + ADD_VALUES)
  fem        Solid.advance (assembly of the nodal forces, central-difference sub-steps)
  update     CoupledSurface.refresh_vertices (VecScatter of the surface nodes, mirror)
  step       Simulation.step (everything, incl. the particle pairs, integration, ghosts)
coupling overhead = search + transfer + update (target <= 15 % of the step).
Writes benchmarks/results/coupled.json.
"""
from __future__ import annotations

import argparse
import json
import time
from pathlib import Path

import pdemfem  # noqa: F401  (environment first)
from mpi4py import MPI

from pdemfem import Simulation
from pdemfem.coupling.surface import CoupledSurface
from pdemfem.fem.solid import Solid
from pdemfem.walls.mesh import TriangleSurface

HERE = Path(__file__).resolve().parent
from method_timers import TIMES, wrap  # noqa: E402  (benchmarks/method_timers.py)


def scene(particles: int, cells):
    per_layer = 87 * 87
    layers = -(-particles // per_layer)
    return {
        "time": {"end": 1.0, "dt": 1.5e-5},
        "gravity": [0, 0, -9.81],
        "materials": {"glass": {"density": 2500, "youngs_modulus": 5e6, "poisson_ratio": 0.3},
                      "rubber": {"density": 1200, "youngs_modulus": 1e8, "poisson_ratio": 0.35}},
        "interactions": {"default": {"model": "hertz_mindlin", "restitution": 0.5, "friction": 0.5}},
        "particles": [{"name": "layer", "material": "glass", "radius": 0.0015,
                       "insert": {"kind": "lattice", "count": particles, "spacing": 0.0032, "jitter": 0.3, "seed": 1,
                                  "velocity": [0.1, 0.0, 0.0],
                                  "region": {"box": [[0.011, 0.011, 0.0202], [0.289, 0.289, 0.0202 + 0.0032 * layers + 0.0001]]}}}],
        "solids": [{"name": "plate", "mesh": {"box": [[0, 0, 0], [0.3, 0.3, 0.02]], "cells": list(cells)},
                    "material": "rubber", "fixed": ["xmin", "xmax", "ymin", "ymax"], "contact": ["zmax"]}],
    }


def main():
    parser = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    parser.add_argument("--particles", type=int, default=20000)
    parser.add_argument("--cells", type=int, nargs=3, default=[64, 64, 3])
    parser.add_argument("--steps", type=int, default=200)
    parser.add_argument("--warmup", type=int, default=300, help="untimed steps (the layer lands)")
    parser.add_argument("--out", default=str(HERE / "results" / "coupled.json"))
    args = parser.parse_args()
    comm = MPI.COMM_WORLD

    start = time.perf_counter()
    sim = Simulation.from_dict(scene(args.particles, args.cells), comm=comm, output_dir="/tmp/pdemfem_coupled_bench")
    build = time.perf_counter() - start
    solid = sim.solids["plate"]
    dof = 3 * solid.n_global_nodes
    sim.step(args.warmup)

    wrap(TriangleSurface, "_rebuild_lists", "search")
    wrap(TriangleSurface, "add_forces", "contacts_incl_search")
    wrap(CoupledSurface, "collect_contact_forces", "transfer")
    wrap(CoupledSurface, "send_forces_to_solid", "transfer")
    wrap(Solid, "advance", "fem")
    wrap(CoupledSurface, "refresh_vertices", "update")
    comm.Barrier()
    start = time.perf_counter()
    sim.step(args.steps)
    comm.Barrier()
    total = time.perf_counter() - start

    surface = sim.coupled_surfaces[0].triangle_surface
    phases = {
        "search": TIMES["search"],
        "contacts": TIMES["contacts_incl_search"] - TIMES["search"],
        "transfer": TIMES["transfer"],
        "fem": TIMES["fem"],
        "update": TIMES["update"],
    }
    phases["rest (particles, pairs, integration)"] = total - sum(phases.values())
    overhead = phases["search"] + phases["transfer"] + phases["update"]
    result = {
        "ranks": comm.size, "particles": sim.particle_count(), "fe_dof": dof,
        "surface_triangles": int(len(surface.triangles)), "steps": args.steps, "dt": sim.dt,
        "fem_substeps": sim.coupling.fem_substeps["plate"], "fe_critical_step": solid.critical_time_step(),
        "build_s": build, "step_ms": 1e3 * total / args.steps,
        "phases_ms_per_step": {k: 1e3 * v / args.steps for k, v in phases.items()},
        "phases_share": {k: v / total for k, v in phases.items()},
        "coupling_overhead_share": overhead / total,
        "surface_contacts_last_step_rank0": int(surface.contact_count),
        "list_builds_rank0": int(surface.list_builds),
    }
    if comm.rank == 0:
        print(f"{result['particles']} particles, {dof} FE DOF, {result['surface_triangles']} surface triangles, "
              f"{comm.size} rank(s), dt {sim.dt:.3g} s, FE sub-steps {result['fem_substeps']}")
        print(f"{'phase':40s} {'ms/step':>9s} {'share':>7s}")
        for k, v in phases.items():
            print(f"{k:40s} {1e3 * v / args.steps:9.3f} {v / total:7.1%}")
        print(f"{'step':40s} {1e3 * total / args.steps:9.3f} {1:7.1%}")
        print(f"coupling overhead (search + transfer + update): {overhead / total:.1%} (target <= 15 %)")
        Path(args.out).parent.mkdir(parents=True, exist_ok=True)
        Path(args.out).write_text(json.dumps(result, indent=2))


if __name__ == "__main__":
    main()

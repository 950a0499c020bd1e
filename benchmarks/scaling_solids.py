"""The FE side of benchmarks/scaling.py: scenes and the timed worker of its `fem` and `coupled` modes.

fem      an aluminium plate (box mesh, P1, lumped mass) clamped at xmin under a traction on zmax, no
         particles: dt auto is the FE critical step, each DEM-free step is one explicit FE step
         (internal force product, ghost scatters).  Strong scaling keeps the cells; weak scaling grows
         the plate along x with the rank count (--cells-per-rank columns of cells per rank).
coupled  the same plate, with its top a contact surface, under a bed of glass spheres settling on it
         (benchmarks/settle.py's materials, dt auto): the whole coupled step (DEM step, counter-forces
         to the nodes, FE sub-steps, surface refresh).

Figures: nodes (or particles) x steps / wall second of the timed steps, and the efficiency
T(1) / (p T(p)) (strong) or T(1) / T(p) (weak), as scaling.py reports for the DEM.
"""
from __future__ import annotations

import os
import tempfile
import time

ALUMINIUM = {"density": 2700.0, "youngs_modulus": 7.0e9, "poisson_ratio": 0.33}
GLASS = {"density": 2500.0, "youngs_modulus": 5.0e6, "poisson_ratio": 0.3}
CELL = 0.01  # m: cells are 1 cm cubes (6 tetrahedra each)


def plate(columns: int, rows: int, layers: int, contact: bool) -> dict:
    return {"name": "plate", "mesh": {"box": [[0.0, 0.0, 0.0], [columns * CELL, rows * CELL, layers * CELL]],
                                      "cells": [columns, rows, layers]},
            "material": "alu", "fixed": ["xmin", "xmax"] if contact else ["xmin"],
            "damping": {"alpha": 200.0, "beta": 0.0},
            **({"contact": ["zmax"]} if contact else {"tractions": [{"group": "zmax", "traction": [0, 0, -1.0e3]}]})}


def fem_scene(columns: int, rows: int, layers: int) -> dict:
    return {"time": {"end": 1.0, "dt": "auto"}, "gravity": [0.0, 0.0, -9.81],
            "materials": {"alu": dict(ALUMINIUM)}, "solids": [plate(columns, rows, layers, contact=False)],
            "output": {"every": 1.0, "particles": [], "solids": []}}


def coupled_scene(columns: int, rows: int, layers: int, particles: int) -> dict:
    """Spheres (d 2 mm) on a compact lattice over the plate's top, side walls around it."""
    import math

    length, width, top = columns * CELL, rows * CELL, layers * CELL
    spacing = 2.04e-3
    per_layer = max(1, int(length / spacing) * int(width / spacing))
    height = (math.ceil(particles / per_layer) + 2) * spacing
    side = {"kind": "plane", "material": "glass"}
    return {"time": {"end": 1.0, "dt": "auto"}, "gravity": [0.0, 0.0, -9.81],
            "materials": {"alu": dict(ALUMINIUM), "glass": dict(GLASS)},
            "interactions": {"default": {"restitution": 0.5, "friction": 0.5}},
            "particles": [{"name": "grains", "material": "glass", "radius": 1.0e-3,
                           "insert": {"kind": "lattice", "count": particles, "spacing": spacing, "seed": 1,
                                      "jitter": 0.2,
                                      "region": {"box": [[0.0, 0.0, top + 0.02e-3], [length, width, top + height]]}}}],
            "walls": [dict(side, name="x_low", point=[0, 0, 0], normal=[1, 0, 0]),
                      dict(side, name="x_high", point=[length, 0, 0], normal=[-1, 0, 0]),
                      dict(side, name="y_low", point=[0, 0, 0], normal=[0, 1, 0]),
                      dict(side, name="y_high", point=[0, width, 0], normal=[0, -1, 0])],
            "solids": [plate(columns, rows, layers, contact=True)],
            "output": {"every": 1.0, "particles": [], "solids": []}}


def worker(args) -> dict:
    """One run on the ranks of COMM_WORLD; rank 0 returns the figures."""
    from mpi4py import MPI

    from pdemfem import Simulation

    comm = MPI.COMM_WORLD
    columns = args.columns if args.study == "strong" else args.columns * comm.size
    if args.mode == "fem":
        scene = fem_scene(columns, args.rows, args.layers)
    else:
        scene = coupled_scene(columns, args.rows, args.layers,
                              args.particles if args.study == "strong" else args.per_rank * comm.size)
    with tempfile.TemporaryDirectory(prefix="scaling-solids-") as scratch:
        build_start = time.perf_counter()
        sim = Simulation.from_dict(scene, comm=comm, output_dir=os.path.join(scratch, "out"))
        build_seconds = comm.allreduce(time.perf_counter() - build_start, op=MPI.MAX)
        sim.step(args.pre_steps)
        comm.Barrier()
        start = time.perf_counter()
        sim.step(args.steps)
        elapsed = comm.allreduce(time.perf_counter() - start, op=MPI.MAX)
        solid = sim.solids["plate"]
        nodes = comm.allreduce(solid.n_owned_nodes)
        particles = sim.particle_count()
        substeps = sim.coupling.fem_substeps["plate"]
    if comm.rank != 0:
        return {}
    return {"ranks": comm.size, "mode": args.mode, "study": args.study, "cells": [columns, args.rows, args.layers],
            "nodes": nodes, "particles": particles, "steps": args.steps, "pre_steps": args.pre_steps,
            "dt": sim.dt, "fem_substeps_per_step": substeps, "wall_seconds": elapsed,
            "build_seconds": build_seconds,
            "node_steps_per_second": nodes * args.steps / elapsed,
            "particle_steps_per_second": particles * args.steps / elapsed if particles else None}

"""Heat conduction for the partition-independence test: explicit and implicit, all boundary kinds.

    python fem_heat_case.py OUT.npz

Writes the temperatures (input-mesh numbering) and the heat books after 10 advances with nodal heat
added from rank 0 only (routed to the owners by PETSc's assembly).
"""
import sys

import numpy as np
from mpi4py import MPI

import pdemfem  # noqa: F401

from pdemfem.fem import Solid, SolidConfig
from pdemfem.scene.schema import MaterialConfig

comm = MPI.COMM_WORLD
# E tiny: the mechanics (refreshed thermal load included) takes a few sub-steps per heat advance
material = MaterialConfig(density=7800.0, youngs_modulus=1e-3, poisson_ratio=0.3, thermal_expansion=1.2e-5,
                          conductivity=50.0, heat_capacity=500.0)


def by_original(solid, values):
    parts = comm.gather((solid.original_node_ids, np.asarray(values)), root=0)
    if comm.rank:
        return None
    ids = np.concatenate([p[0] for p in parts])
    return np.concatenate([p[1] for p in parts])[np.argsort(ids)]


def run(scheme, limits=4):
    config = SolidConfig(name="block", mesh={"box": [[0, 0, 0], [0.3, 0.1, 0.1]], "cells": [6, 2, 2]}, material="m",
                         initial_temperature=300.0, reference_temperature=300.0,
                         thermal={"scheme": scheme, "fixed": [{"group": "xmax", "temperature": 400.0}],
                                  "flux": [{"group": "xmin", "flux": 2e4}],
                                  "convection": [{"group": "zmax", "coefficient": 50.0, "ambient": 280.0}]})
    solid = Solid(config, material, gravity=(0.0, 0.0, 0.0), comm=comm)
    # every 7th node of the input mesh, by its global number (which depends on the partition)
    first = solid.global_node_range[0]
    pairs = comm.allgather((solid.original_node_ids, first + np.arange(solid.n_owned_nodes)))
    global_of_original = np.empty(solid.n_global_nodes, dtype=np.int64)
    for original, numbers in pairs:
        global_of_original[original] = numbers
    surface = global_of_original[::7]
    interval = limits * solid.heat_critical_time_step()  # explicit: `limits` sub-steps per advance
    for n in range(10):
        if comm.rank == 0:
            solid.add_nodal_heat(surface, np.full(len(surface), 2.0 + np.sin(n)))
        solid.advance(interval)
    books = np.array(list(solid.boundary_heat().values()) + [solid.nodal_heat_added, solid.thermal_energy()])
    return by_original(solid, solid.temperatures), books


def enclosed():
    """Every face held, one interior node, implicit steps of 1000 limits: the constrained operator is diagonal
    (GAMG cannot coarsen it; Jacobi must be chosen)."""
    held = [{"group": face, "temperature": 350.0} for face in ("xmin", "xmax", "ymin", "ymax", "zmin", "zmax")]
    config = SolidConfig(name="cube", mesh={"box": [[0, 0, 0], [0.1, 0.1, 0.1]], "cells": [2, 2, 2]}, material="m",
                         initial_temperature=300.0, thermal={"scheme": "implicit", "fixed": held})
    solid = Solid(config, material, gravity=(0.0, 0.0, 0.0), comm=comm)
    for _ in range(3):
        solid.heat.advance(1000 * solid.heat_critical_time_step())
    return by_original(solid, solid.temperatures)


explicit, explicit_books = run("explicit")
implicit, implicit_books = run("implicit")
# 50 limits per advance: CG + GAMG
implicit_long, implicit_long_books = run("implicit", limits=50)
enclosed_temperatures = enclosed()
if comm.rank == 0:
    np.savez(sys.argv[1], explicit=explicit, implicit=implicit, explicit_books=explicit_books,
             implicit_books=implicit_books, implicit_long=implicit_long, implicit_long_books=implicit_long_books,
             enclosed=enclosed_temperatures, ranks=comm.size)

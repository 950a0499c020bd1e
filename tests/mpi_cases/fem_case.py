"""One FEM run for the partition-independence test: static start, then 100 explicit steps.

    python fem_case.py OUT_DIR ELEMENT [ELEMENT ...]      -> OUT_DIR/ELEMENT.npz

Writes, in input-mesh numbering: static displacements and von Mises stresses, the displacements
after 100 explicit steps with nodal forces added from rank 0 only (routed by PETSc assembly),
and a second solid's displacements after 100 steps from rest (no linear solve: pure round-off).
"""
import sys

import numpy as np
from mpi4py import MPI

import pdemfem  # noqa: F401
from petsc4py import PETSc

from pdemfem.fem import Solid, SolidConfig
from pdemfem.scene.schema import MaterialConfig

RTOL = 1e-12  # static solve tolerance (true residual); the test's bound scales with it

out_dir, elements = sys.argv[1], sys.argv[2:]
comm = MPI.COMM_WORLD
PETSc.Options().setValue("fem_ksp_rtol", RTOL)
steel = MaterialConfig(density=7800.0, youngs_modulus=2e11, poisson_ratio=0.3, thermal_expansion=1.2e-5)


def config(element, **keys):
    return SolidConfig(name="block", mesh={"box": [[0, 0, 0], [3.0, 1.0, 1.0]], "cells": [6, 2, 2]}, material="steel",
                       element=element, **keys)


def by_original(solid, values):
    """Rank 0: values (owned rows) of every rank, ordered by input node number."""
    parts = comm.gather((solid.original_node_ids, np.asarray(values)), root=0)
    if comm.rank:
        return None
    ids = np.concatenate([p[0] for p in parts])
    data = np.concatenate([p[1] for p in parts])
    return data[np.argsort(ids)]


def cells_by_original(solid, values):
    parts = comm.gather((solid.original_cell_ids, np.asarray(values)), root=0)
    if comm.rank:
        return None
    ids = np.concatenate([p[0] for p in parts])
    return np.concatenate([p[1] for p in parts])[np.argsort(ids)]



def run(element):
    solid = Solid(config(element, fixed=["xmin"], tractions=[{"group": "xmax", "traction": [1e6, 0.0, -2e6]}], contact=["zmax"],
                         initial_temperature=350.0, reference_temperature=293.15), steel, comm=comm)
    result = solid.static_solve()
    static_u = by_original(solid, solid.displacements)
    static_vm = cells_by_original(solid, solid.von_mises)
    reaction = solid.reaction("xmin")

    nodes, positions, velocities = solid.surface_state()
    triangles = solid.surface_triangles()
    # the gathered surface positions equal the owners' values on every rank
    owned = (nodes >= solid.global_node_range[0]) & (nodes < solid.global_node_range[1])
    local_rows = nodes[owned] - solid.global_node_range[0]
    surface_ok = np.array_equal(positions[owned], solid.positions[local_rows])
    surface_ok = comm.allreduce(bool(surface_ok), op=MPI.LAND)
    # every rank sees the same surface
    digest = np.array([positions.sum(), float(triangles.sum()), float(len(triangles))])
    digests = comm.allgather(digest)
    surface_ok = surface_ok and all(np.array_equal(d, digests[0]) for d in digests)

    dt = 0.9 * solid.critical_time_step()
    for n in range(100):
        if comm.rank == 0:  # rank 0 pushes on every surface node, wherever it is owned
            solid.add_nodal_forces(nodes, np.tile([0.0, 1e3 * np.sin(n * 0.1), -2e3], (len(nodes), 1)))
        solid.step(dt)
    dynamic_u = by_original(solid, solid.displacements)
    work, kinetic = solid.external_work, solid.kinetic_energy()

    at_rest = Solid(config(element, fixed=["xmin"]), steel, comm=comm)
    for n in range(100):
        at_rest.step(0.9 * at_rest.critical_time_step())
    rest_u = by_original(at_rest, at_rest.displacements)

    if comm.rank == 0:
        np.savez(f"{out_dir}/{element}.npz", static_u=static_u, static_vm=static_vm, reaction=reaction, dynamic_u=dynamic_u, rest_u=rest_u,
                 work=work, kinetic=kinetic, iterations=result.iterations, residual=result.residual_norm, rhs=result.rhs_norm,
                 surface_ok=surface_ok, n_triangles=len(triangles), ranks=comm.size)


for element in elements:
    run(element)

"""Shared builders for the FEM tests (small meshes, explicit options)."""
from __future__ import annotations

import contextlib

import numpy as np
from mpi4py import MPI

import pdemfem  # noqa: F401  (PETSc environment first)
from pdemfem.fem import Solid, SolidConfig
from pdemfem.scene.schema import MaterialConfig


def material(E=1000.0, nu=0.3, rho=1.0, alpha=0.0) -> MaterialConfig:
    return MaterialConfig(density=rho, youngs_modulus=E, poisson_ratio=nu, thermal_expansion=alpha)


def box_solid(low, high, cells, mat, gravity=(0.0, 0.0, 0.0), comm=MPI.COMM_WORLD, **keys) -> Solid:
    config = SolidConfig(name=keys.pop("name", "body"), mesh={"box": [list(low), list(high)], "cells": list(cells)},
                         material="m", **keys)
    return Solid(config, mat, gravity=gravity, comm=comm)


@contextlib.contextmanager
def petsc_options(**values):
    """Set PETSc options (names without the leading dash) for the block, then remove them."""
    from petsc4py import PETSc

    options = PETSc.Options()
    for key, value in values.items():
        options.setValue(key, value)
    try:
        yield
    finally:
        for key in values:
            options.delValue(key)


def direct_solver():
    """LU instead of CG+GAMG, through the fem_ options prefix: results to round-off (serial only)."""
    return petsc_options(fem_ksp_type="preonly", fem_pc_type="lu")


def dense(matrix) -> np.ndarray:
    from petsc4py import PETSc

    return matrix.convert("dense", out=PETSc.Mat()).getDenseArray().copy()


def unstructured_box_msh(path, size=0.35, second_box=False) -> str:
    """A gmsh-meshed (unstructured) unit box with physical groups 'boundary' (all faces), 'bottom' and 'volume'."""
    import gmsh

    gmsh.initialize(interruptible=False)
    try:
        gmsh.option.setNumber("General.Terminal", 0)
        gmsh.model.add("patch")
        box = gmsh.model.occ.addBox(0, 0, 0, 1, 1, 1)
        gmsh.model.occ.synchronize()
        surfaces = [tag for _, tag in gmsh.model.getEntities(2)]
        bottom = [s for s in surfaces if abs(gmsh.model.occ.getCenterOfMass(2, s)[2]) < 1e-12]
        gmsh.model.addPhysicalGroup(2, surfaces, name="boundary")
        gmsh.model.addPhysicalGroup(2, bottom, name="bottom")
        gmsh.model.addPhysicalGroup(3, [box], name="volume")
        gmsh.option.setNumber("Mesh.MeshSizeMax", size)
        gmsh.option.setNumber("Mesh.MeshSizeMin", size)
        gmsh.model.mesh.generate(3)
        gmsh.write(str(path))
    finally:
        gmsh.finalize()
    return str(path)

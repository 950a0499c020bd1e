"""Parallel finite elements for deformable solids (linear thermo-elastic tetrahedra on PETSc).

Public API: SolidConfig (scene keys, pdemfem.fem.config) and Solid (pdemfem.fem.solid).
See docs/fem.md.  Importing this package does not import petsc4py; Solid does.
"""
from pdemfem.fem.config import SolidConfig

__all__ = ["SolidConfig", "Solid"]


def __getattr__(name):
    if name == "Solid":
        from pdemfem.fem.solid import Solid

        return Solid
    raise AttributeError(name)

"""petsc4py's PETSc, as the package imports it: `from pdemfem.fem.petsc import PETSc`.

Loading PETSc loads the libraries it links, and one of Debian's (SuperLU_DIST) changes glibc's
malloc for the whole process in its constructor: no block is mapped on its own any more, and the
heap is never trimmed, so the arrays a list rebuild frees stay resident as heap fragments.  The
settings pdemfem.runtime makes at import are made again here, after that constructor has run.
"""
from petsc4py import PETSc

from pdemfem.runtime import fix_malloc

fix_malloc()

__all__ = ["PETSc"]

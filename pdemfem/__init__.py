"""pdemfem: an MPI-parallel coupled discrete element / finite element solver on PETSc."""
from pdemfem import runtime as _runtime

# petsc4py locates PETSc through PETSC_DIR; set it (and the MPI variables) before
# anything imports petsc4py or mpi4py.
_runtime.apply_to_this_process()

__version__ = "0.1.0"


def __getattr__(name):
    # Lazy so that `import pdemfem` stays cheap (no numba compile, no MPI init).
    if name == "Simulation":
        from pdemfem.simulation import Simulation

        return Simulation
    raise AttributeError(name)


__all__ = ["Simulation", "__version__"]

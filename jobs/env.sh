# Environment for pdemfem jobs on a cluster: sourced by every template in jobs/.
# Adapt the module names and paths to your site, once, here.
#
# Modules (examples; `module avail` lists your site's names).  mpi4py, petsc4py and h5py
# must be built against the MPI you load (h5py with parallel HDF5 for collective output):
#   module purge
#   module load gcc/12 openmpi/4.1 hdf5/1.14-mpi petsc/3.18 python/3.11
#
# PETSc: the installation petsc4py was built against (the module usually sets it).
export PETSC_DIR="${PETSC_DIR:-/usr/lib/petscdir/petsc3.18/x86_64-linux-gnu-real}"
# export PETSC_ARCH=arch-linux-c-opt        # only for an in-tree PETSc build

# The project's virtual environment (created with --system-site-packages so that the
# cluster's mpi4py/petsc4py/h5py are used).
PDEMFEM_HOME="${PDEMFEM_HOME:-$HOME/pdemfem}"
source "$PDEMFEM_HOME/.venv/bin/activate"

# One thread per rank: ranks, not threads, use the cores (numba, BLAS, OpenMP).
export NUMBA_NUM_THREADS=1 OMP_NUM_THREADS=1 OPENBLAS_NUM_THREADS=1 MKL_NUM_THREADS=1
# Collective HDF5 output through h5py's mpio driver.
export H5PY_ALWAYS_USE_MPI=1
# numba's compiled-kernel cache: on a shared file system every rank would compile at once;
# point it at a directory all ranks share (compiled once, by the first job).
export NUMBA_CACHE_DIR="${NUMBA_CACHE_DIR:-$PDEMFEM_HOME/.numba_cache}"

# `python -m pdemfem.launch --print-env` prints the variables pdemfem sets for a laptop run;
# do NOT copy its Open MPI oversubscription / run-as-root lines into a cluster job.

"""Process-level environment, kept in one place.

The Makefile, the test suite and the CLI all take PETSC_DIR, the Open MPI
variables needed to run as root, oversubscription and thread pinning from here,
so nothing of it is copied around.  Usage from a shell::

    python -m pdemfem.launch -n 2 -- pdemfem run scene.yaml   # mpiexec with the right environment
    python -m pdemfem.launch --print-env                      # export lines for a job script
"""
from __future__ import annotations

import functools
import glob
import hashlib
import os
import shutil
import sys
from pathlib import Path

# Debian installs PETSc under /usr/lib/petscdir/petscX.Y/<triplet>-real; the
# /usr/lib/petsc alternative exists only with petsc-dev, and petsc4py needs PETSC_DIR.
_DEBIAN_PETSC_PATTERN = "/usr/lib/petscdir/petsc*/*-linux-gnu-real"


def find_petsc_dir() -> str | None:
    """PETSC_DIR from the environment, else the newest Debian PETSc, else None."""
    configured = os.environ.get("PETSC_DIR")
    if configured:
        return configured
    candidates = sorted(glob.glob(_DEBIAN_PETSC_PATTERN))
    return candidates[-1] if candidates else None


@functools.lru_cache(maxsize=1)
def source_digest() -> str:
    """A digest of every source file of the package (16 hex digits): names the kernel cache folders."""
    digest = hashlib.sha256()
    package = Path(__file__).resolve().parent
    for path in sorted(package.rglob("*.py")):
        digest.update(str(path.relative_to(package)).encode())
        digest.update(path.read_bytes())
    return digest.hexdigest()[:16]


@functools.lru_cache(maxsize=1)
def kernel_cache_directory() -> str | None:
    """Where numba caches the compiled kernels: one folder per version of the package's source.

    numba keys a cached kernel on its own file's time stamp only; a kernel that inlines a function from
    another module (the contact law into the wall kernels) would keep running the old law after that
    module changed.  A folder named by a digest of every source file of the package cannot go stale."""
    base = os.environ.get("XDG_CACHE_HOME") or os.path.join(os.path.expanduser("~"), ".cache")
    directory = os.path.join(base, "pdemfem", "numba", source_digest())
    try:
        os.makedirs(directory, exist_ok=True)
    except OSError:
        return None  # no writable home: numba's own default (__pycache__ beside the sources)
    return directory


# What an initialised MPI process leaves in its environment for itself (its PMIx server, its singleton
# launch): an mpiexec started from it (or from its children) takes them for its own and exits 1 silently.
INHERITED_MPI_PREFIXES = ("PMIX_", "OMPI_MCA_ess", "OMPI_MCA_pmix", "OMPI_MCA_orte_launch", "OMPI_MCA_orte_ess",
                          "OMPI_MCA_orte_hnp", "OMPI_COMM_WORLD_", "OMPI_UNIVERSE_SIZE", "OMPI_FILE_LOCATION")


def process_environment(base: dict | None = None) -> dict:
    """The environment a pdemfem process (or an mpiexec launching them) needs: the base (os.environ)
    without what an MPI process already running left for itself, plus pdemfem's settings."""
    environment = {key: value for key, value in (os.environ if base is None else base).items()
                   if not key.startswith(INHERITED_MPI_PREFIXES)}
    petsc_dir = find_petsc_dir()
    if petsc_dir and "PETSC_DIR" not in environment:
        environment["PETSC_DIR"] = petsc_dir
    if hasattr(os, "geteuid") and os.geteuid() == 0:
        environment.setdefault("OMPI_ALLOW_RUN_AS_ROOT", "1")
        environment.setdefault("OMPI_ALLOW_RUN_AS_ROOT_CONFIRM", "1")
    # More ranks than cores is how decomposition is tested on small machines.
    environment.setdefault("OMPI_MCA_rmaps_base_oversubscribe", "1")
    # A user error already printed one clear message; mpiexec's extra "process returned a
    # non-zero exit code" banner would bury it.
    environment.setdefault("OMPI_MCA_orte_execute_quiet", "1")
    # Containers often forbid cross-memory attach; without this Open MPI prints
    # errors on every large shared-memory message.
    environment.setdefault("OMPI_MCA_btl_vader_single_copy_mechanism", "none")
    # Debian's h5py picks its MPI build only under mpiexec; use it always so a
    # one-process run writes through the same (collective) code path.
    environment.setdefault("H5PY_ALWAYS_USE_MPI", "1")
    # One thread per rank: MPI ranks are the parallelism, BLAS threads would compete.
    for variable in ("OMP_NUM_THREADS", "OPENBLAS_NUM_THREADS", "MKL_NUM_THREADS", "NUMBA_NUM_THREADS"):
        environment.setdefault(variable, "1")
    # Where colorama is installed (many tools bring it), numba builds its error messages through it from the
    # first kernel loaded, which registers a terminal reset ("\x1b[0m") written to stdout at every exit:
    # a quiet run's output would not be empty, and log files would hold escape codes.
    environment.setdefault("NUMBA_DISABLE_ERROR_MESSAGE_HIGHLIGHTING", "1")
    # A cluster job may point numba elsewhere (jobs/README.md); otherwise a folder per source version.
    cache = kernel_cache_directory()
    if cache is not None:
        environment.setdefault("NUMBA_CACHE_DIR", cache)
    return environment


# glibc's malloc serves a block above this size with its own mapping, given back to the system when freed.
MALLOC_MMAP_THRESHOLD_BYTES = 1 << 20
_M_MMAP_THRESHOLD = -3  # mallopt's parameter number (malloc.h)


def fix_malloc_mmap_threshold() -> bool:
    """Keep blocks of a megabyte and more out of the heap (glibc).  A list rebuild allocates and frees
    several such arrays (the contact records, their look-up tables, a re-sort's per-particle arrays);
    glibc by default raises its mmap threshold to the largest block freed so far, after which they are
    carved from the heap, whose freed fragments stay resident.  On the settle benchmark's first 3000
    steps (115 rebuilds) the resident set rose by 967 B per particle by default and 596 B with this
    threshold, rebuilds taking the same CPU time (0.59 s); a 128 KiB threshold gave 457 B but nearly
    doubled the rebuilds' time (page faults on every smaller array too).  A MALLOC_MMAP_THRESHOLD_ set
    by the user wins.  Returns whether the threshold was set."""
    if os.environ.get("MALLOC_MMAP_THRESHOLD_") or not sys.platform.startswith("linux"):
        return False
    try:
        import ctypes

        mallopt = ctypes.CDLL(None).mallopt
    except (OSError, AttributeError):  # not glibc (musl has no mallopt)
        return False
    return bool(mallopt(_M_MMAP_THRESHOLD, MALLOC_MMAP_THRESHOLD_BYTES))


def apply_to_this_process() -> None:
    """Set the variables in os.environ before petsc4py / mpi4py are imported (and fix malloc's
    mmap threshold: fix_malloc_mmap_threshold).

    Debian's petsc4py is put on sys.path by a .pth file that reads PETSC_DIR when
    the interpreter starts; when PETSC_DIR was not set then, add the path here.
    """
    for key, value in process_environment().items():
        if os.environ.get(key) != value:
            os.environ[key] = value
    fix_malloc_mmap_threshold()
    petsc_dir = os.environ.get("PETSC_DIR")
    if petsc_dir:
        petsc_python_path = os.path.join(petsc_dir, "lib", "python3", "dist-packages")
        if os.path.isdir(petsc_python_path) and petsc_python_path not in sys.path:
            sys.path.append(petsc_python_path)


def mpiexec_executable() -> str:
    for name in ("mpiexec", "mpirun"):
        path = shutil.which(name)
        if path:
            return path
    raise FileNotFoundError("mpiexec not found: install Open MPI (make install) or load your cluster's MPI module")


def mpiexec_command(ranks: int, command: list[str]) -> list[str]:
    """Command line that runs `command` on `ranks` MPI processes."""
    return [mpiexec_executable(), "-n", str(ranks), *command]

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
    # hwloc's GL component (Debian's libhwloc-plugins) connects every MPI process to the X displays :0, :1, ...
    # to look for GPUs; when such a server goes away (a virtual one `pdemfem render` started for ParaView),
    # Xlib ends the process: "X connection to :0 broken", exit 1 mid-run.  Its topology needs no GPUs.
    environment.setdefault("HWLOC_COMPONENTS", "-gl")
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
MALLOC_MMAP_THRESHOLD_BYTES = 1 << 19
# Free memory at the top of the heap is given back above this much (glibc's own largest dynamic value is twice
# its largest mmap threshold, 64 MiB); at 2 MiB a settle run's rebuilds page-faulted 500 times each
# (82,000 faults in 165 rebuilds against 3,000) and took 16 % longer.
MALLOC_TRIM_THRESHOLD_BYTES = 32 << 20
GLIBC_DEFAULT_MMAP_MAX = 65536  # how many blocks may be mapped at once (glibc's default)
# (mallopt's parameter number (malloc.h), the environment variable by which a user sets it, pdemfem's value)
_MALLOC_SETTINGS = ((-4, "MALLOC_MMAP_MAX_", GLIBC_DEFAULT_MMAP_MAX),
                    (-3, "MALLOC_MMAP_THRESHOLD_", MALLOC_MMAP_THRESHOLD_BYTES),
                    (-1, "MALLOC_TRIM_THRESHOLD_", MALLOC_TRIM_THRESHOLD_BYTES))


def fix_malloc() -> bool:
    """Keep blocks of half a megabyte and more out of the heap (glibc).  A list rebuild allocates and frees
    several such arrays (the contact records, their look-up tables, a re-sort's per-particle arrays);
    glibc by default raises its mmap threshold to the largest block freed so far, after which they are
    carved from the heap, whose freed fragments stay resident.

    Called at import and again once PETSc is loaded (pdemfem.fem.petsc): Debian's PETSc links
    SuperLU_DIST, whose library constructor turns mapped blocks off (M_MMAP_MAX = 0) and the heap's
    trimming off for the whole process, so every block, however large, came from the heap.  Resident
    set rise over the settle benchmark's first 8000 steps (28,000 particles), B per particle:
    1,110-1,355 with SuperLU_DIST's settings, 924-1,067 with a 1 MiB threshold, 829-903 with 512 KiB
    (rebuilds' time within the noise: 30,000 more page faults in 8000 steps, ~0.1 s of 32 s).  A
    smaller threshold costs time (every smaller array page-faults afresh at each rebuild: ~4 us a
    page on this machine): at 256 KiB the rebuilds took ~1.15x the CPU time, at 128 KiB 1.7x.  The
    same holds for any threshold once a per-particle array outgrows it (a 3-vector at 21,846 particles a
    rank, one float64 at 65,536): a rebuild's fresh arrays then page-fault, the price of giving their
    memory back; the arrays a rebuild would make anew every time are kept buffers instead
    (ParticleState.reorder's scratch, the list build's sorted positions).  A
    variable set by the user (MALLOC_MMAP_THRESHOLD_, MALLOC_MMAP_MAX_, MALLOC_TRIM_THRESHOLD_) wins.
    Returns whether the settings were made."""
    if not sys.platform.startswith("linux"):
        return False
    try:
        import ctypes

        mallopt = ctypes.CDLL(None).mallopt
    except (OSError, AttributeError):  # not glibc (musl has no mallopt)
        return False
    made = True
    for number, variable, value in _MALLOC_SETTINGS:
        if not os.environ.get(variable):
            made = bool(mallopt(number, value)) and made
    return made


def apply_to_this_process() -> None:
    """Set the variables in os.environ before petsc4py / mpi4py are imported (and make pdemfem's
    malloc settings: fix_malloc).

    Debian's petsc4py is put on sys.path by a .pth file that reads PETSC_DIR when
    the interpreter starts; when PETSC_DIR was not set then, add the path here.
    """
    for key, value in process_environment().items():
        if os.environ.get(key) != value:
            os.environ[key] = value
    fix_malloc()
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

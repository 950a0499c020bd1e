"""The contact kernels (pair_forces, plane_wall_forces) compiled for one scene's composition.

The kernels take the composition (the sub-models a scene uses) as an argument and test it per
contact; compiled for a fixed one, the compiler folds those tests and drops the unused sub-models,
and the pair loop of the settle benchmark's bed took 11 % less time (docs/performance.md).  numba
folds a module's global constants, but caches a kernel on disk only when it lives in a file of its
own: so each composition gets a copy of pdemfem/contact/forces.py with COMPILED_COMPOSITION set,
written once into a folder per version of the package's source (module_folder), and imported from
there.  The first run of a composition compiles its kernels (about 15 s, and 10 s more for the pair loop of
first evaluations at the first contact); later runs load them from the
cache like every other kernel.

Results agree with the generic kernels' to round-off (tests/test_contact_specialized.py).  Without a
writable folder the generic kernels run (on every rank: ParticleSystem agrees on one choice).
"""
from __future__ import annotations

import functools
import importlib.util
import logging
import os
import sys
import tempfile
from pathlib import Path
from types import ModuleType

from pdemfem.contact import forces
from pdemfem.runtime import kernel_cache_directory, source_digest

log = logging.getLogger("pdemfem")

_MARKER = "COMPILED_COMPOSITION = -1\n"


def specialized_source(composition: int) -> str:
    """forces.py's text with its kernels compiled for `composition`."""
    source = Path(forces.__file__).read_text()
    if source.count(_MARKER) != 1:
        raise RuntimeError(f"{forces.__file__} must hold the line {_MARKER!r} exactly once")
    return source.replace(_MARKER, f"COMPILED_COMPOSITION = {int(composition)}\n")


def module_folder() -> Path | None:
    """Where the composition modules go (None: nowhere writable).  One folder per version of the package's
    source: beside numba's cache when a job points NUMBA_CACHE_DIR elsewhere (a cluster's shared cache,
    jobs/env.sh), in the kernel cache folder otherwise."""
    configured = os.environ.get("NUMBA_CACHE_DIR")
    default = kernel_cache_directory()
    if configured and (default is None or os.path.abspath(configured) != os.path.abspath(default)):
        return Path(configured) / f"pdemfem-specialized-{source_digest()}"
    return None if default is None else Path(default) / "specialized"


def _write_once(path: Path, text: str) -> None:
    """Create `path` holding `text` unless it exists, atomically: the ranks of a run (on one node or on
    several sharing the folder) race to write it, and numba keys its cache on the file's time stamp, so a
    file rewritten after one rank compiled it would make the next run compile again."""
    if path.exists():
        return
    descriptor, temporary = tempfile.mkstemp(prefix=f"{path.name}.", suffix=".tmp", dir=path.parent)
    try:
        with os.fdopen(descriptor, "w") as stream:
            stream.write(text)
        os.link(temporary, path)  # fails if another process created it first
    except FileExistsError:
        pass
    finally:
        os.unlink(temporary)


@functools.lru_cache(maxsize=None)
def contact_kernels(composition: int) -> ModuleType:
    """A module with pair_forces and plane_wall_forces compiled for `composition` (the generic module,
    pdemfem.contact.forces, when no cache folder is writable)."""
    folder = module_folder()
    if folder is None:
        return forces
    name = f"pdemfem_contact_forces_{int(composition)}"
    path = folder / f"{name}.py"
    try:
        path.parent.mkdir(parents=True, exist_ok=True)
        _write_once(path, specialized_source(composition))
    except OSError as error:
        log.info("contact kernels: %s (%s); running the generic kernels", path, error)
        return forces
    spec = importlib.util.spec_from_file_location(name, path)
    module = importlib.util.module_from_spec(spec)
    sys.modules[name] = module
    spec.loader.exec_module(module)
    return module

"""glibc's malloc settings survive PETSc's libraries (pdemfem.runtime.fix_malloc, pdemfem.fem.petsc).

Debian's PETSc links SuperLU_DIST, whose constructor turns mapped blocks and heap trimming off for the
whole process; a list rebuild's freed multi-megabyte arrays then stayed resident as heap fragments.
Each case runs in a fresh interpreter: the constructor runs once per process, at PETSc's first load.
"""
import os
import subprocess
import sys
import textwrap

import pytest

from pdemfem.runtime import MALLOC_MMAP_THRESHOLD_BYTES, process_environment

pytestmark = pytest.mark.skipif(not sys.platform.startswith("linux"), reason="glibc's malloc, /proc/self/maps")

PROBE = textwrap.dedent(f"""
    import numpy as np
    import pdemfem.simulation  # loads PETSc through pdemfem.fem.petsc

    def in_heap(array):
        address = array.ctypes.data
        for line in open("/proc/self/maps"):
            fields = line.split()
            low, high = (int(value, 16) for value in fields[0].split("-"))
            if low <= address < high:
                return len(fields) > 5 and fields[5] == "[heap]"
        raise AssertionError("the array's address is in no mapping")

    # A large block freed first: glibc's default raises its threshold to its size (dynamic threshold).
    freed = np.ones(4 << 20)
    del freed
    block = np.ones(2 * {MALLOC_MMAP_THRESHOLD_BYTES} // 8)  # twice the threshold
    superlu = any("superlu_dist" in line for line in open("/proc/self/maps"))
    print(in_heap(block), superlu)
""")


def _probe(extra_environment=None):
    environment = {**os.environ, **process_environment(), **(extra_environment or {})}
    result = subprocess.run([sys.executable, "-c", PROBE], env=environment, capture_output=True, text=True,
                            timeout=300)
    assert result.returncode == 0, result.stderr
    in_heap, superlu_loaded = result.stdout.split()[-2:]
    return in_heap == "True", superlu_loaded == "True"


def test_blocks_above_the_threshold_are_mapped_after_petsc_loads():
    in_heap, superlu_loaded = _probe()
    # Mapped on its own, so freeing it gives the memory back (with SuperLU_DIST's settings it came from the heap).
    assert not in_heap, f"a {2 * MALLOC_MMAP_THRESHOLD_BYTES >> 20} MiB block came from the heap " \
                        f"(SuperLU_DIST loaded: {superlu_loaded})"


def test_a_setting_made_by_the_user_wins():
    in_heap, _ = _probe({"MALLOC_MMAP_MAX_": "0"})  # the user asks for no mapped blocks at all
    assert in_heap

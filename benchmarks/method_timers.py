"""Wall time and calls of named methods, summed per label: the phase timers the benchmarks wrap around
the solver's own methods (the wrapper costs two perf_counter calls per call)."""
from __future__ import annotations

import time
from collections import defaultdict

TIMES = defaultdict(float)
CALLS = defaultdict(int)


def wrap(cls, name: str, label: str) -> None:
    """Replace cls.name by a wrapper adding its wall time to TIMES[label] and one to CALLS[label]."""
    original = getattr(cls, name)

    def timed(*args, **kwargs):
        start = time.perf_counter()
        try:
            return original(*args, **kwargs)
        finally:
            TIMES[label] += time.perf_counter() - start
            CALLS[label] += 1

    setattr(cls, name, timed)

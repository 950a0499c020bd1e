"""A float64 row buffer kept from call to call, for arrays a rebuild would otherwise make anew.

A fresh megabyte array at every rebuild is mapped afresh by malloc (above its mmap threshold,
pdemfem.runtime.fix_malloc) and page-faulted as it is written, or leaves heap fragments that stay
resident; a kept buffer is written warm.  Callers use its leading rows.
"""
from __future__ import annotations

import numpy as np

# Given back when more than this many times the rows needed (e.g. many particles left the domain).
SLACK = 4
# Rows beyond 1.25x the rows needed when the buffer is made anew: room for the next calls to grow into.
SPARE_ROWS = 1024


class KeptRows:
    def __init__(self, width: int = 0):
        self.rows = np.zeros((0, width))

    def at_least(self, count: int, width: int) -> np.ndarray:
        """The buffer, made anew when it has fewer than `count` rows, more than SLACK times as many (plus the
        spare rows), or another width; its leading `count` rows are the caller's (contents undefined when new)."""
        if self.rows.shape[1] != width or not count <= len(self.rows) <= SLACK * count + SPARE_ROWS:
            self.rows = np.empty((int(1.25 * count) + SPARE_ROWS, width))
        return self.rows

    def leads(self, array: np.ndarray) -> bool:
        """Whether `array` is the buffer's leading rows (a view that starts where the buffer starts, rows in order):
        then the rows after it are free to write."""
        return (array.ndim == 2 and array.shape[1] == self.rows.shape[1] and len(array) <= len(self.rows)
                and array.strides == self.rows.strides
                and array.__array_interface__["data"][0] == self.rows.__array_interface__["data"][0])

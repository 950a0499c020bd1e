"""Half Verlet list in CSR form over cell-sorted particles, with history carry-over.

A pair (i, j), i < j in the current order, is listed when the surfaces are
closer than `skin`; the list stays valid until some particle has moved more
than skin/2 (checked in the drift kernel).  Tangential history lives aligned
with the list and is carried across a rebuild by the partners' global ids.
"""
from __future__ import annotations

import numpy as np
from numba import njit

from pdemfem.neighbors.cells import cell_grid, cell_indices, cell_starts


@njit(cache=True)
def _count_or_fill(positions, radii, skin, cell_of, starts, dimensions, offsets, partners, fill):
    count = positions.shape[0]
    nx, ny, nz = dimensions[0], dimensions[1], dimensions[2]
    for i in range(count):
        cell = cell_of[i]
        cx = cell % nx
        cy = (cell // nx) % ny
        cz = cell // (nx * ny)
        written = 0
        for dz in range(-1, 2):
            z = cz + dz
            if z < 0 or z >= nz:
                continue
            for dy in range(-1, 2):
                y = cy + dy
                if y < 0 or y >= ny:
                    continue
                for dx in range(-1, 2):
                    x = cx + dx
                    if x < 0 or x >= nx:
                        continue
                    neighbour_cell = x + nx * (y + ny * z)
                    for j in range(starts[neighbour_cell], starts[neighbour_cell + 1]):
                        if j <= i:
                            continue
                        ddx = positions[i, 0] - positions[j, 0]
                        ddy = positions[i, 1] - positions[j, 1]
                        ddz = positions[i, 2] - positions[j, 2]
                        cutoff = radii[i] + radii[j] + skin
                        if ddx * ddx + ddy * ddy + ddz * ddz < cutoff * cutoff:
                            if fill:
                                partners[offsets[i] + written] = j
                            written += 1
        if not fill:
            offsets[i + 1] = written


class VerletList:
    """offsets (n+1), partners (int32), history (pairs, 3) aligned with partners."""

    def __init__(self):
        self.offsets = np.zeros(1, dtype=np.int64)
        self.partners = np.zeros(0, dtype=np.int32)
        self.history = np.zeros((0, 3))
        self.builds = 0

    @property
    def pair_count(self) -> int:
        return len(self.partners)

    def rebuild(self, state, skin: float) -> None:
        """Sort particles by cell, rebuild the list, carry tangential history over."""
        count = state.count
        old_keys, old_history = self._active_history(state.ids)
        if count == 0:
            self.offsets = np.zeros(1, dtype=np.int64)
            self.partners = np.zeros(0, dtype=np.int32)
            self.history = np.zeros((0, 3))
            return
        cell_size = 2.0 * float(state.radii.max()) + skin
        lower, cell_size, dimensions = cell_grid(state.positions, cell_size)
        cells = cell_indices(state.positions, lower, cell_size, dimensions)
        permutation = np.argsort(cells, kind="stable")
        state.reorder(permutation)
        cells = np.ascontiguousarray(cells[permutation])
        starts = cell_starts(cells, int(np.prod(dimensions)))
        offsets = np.zeros(count + 1, dtype=np.int64)
        partners = np.zeros(0, dtype=np.int32)
        _count_or_fill(state.positions, state.radii, skin, cells, starts, dimensions, offsets, partners, False)
        np.cumsum(offsets, out=offsets)
        partners = np.empty(offsets[-1], dtype=np.int32)
        _count_or_fill(state.positions, state.radii, skin, cells, starts, dimensions, offsets, partners, True)
        self.offsets = offsets
        self.partners = partners
        self.history = np.zeros((len(partners), 3))
        self._restore_history(state.ids, old_keys, old_history)
        state.positions_at_build[:] = state.positions
        self.builds += 1

    def _pair_ids(self, ids):
        first = np.repeat(ids, np.diff(self.offsets))
        second = ids[self.partners]
        return first, second

    def _active_history(self, ids):
        """Keys (lower id, higher id) and history oriented for the lower id, of springs in use."""
        if self.pair_count == 0 or len(self.offsets) != len(ids) + 1:
            return np.zeros(0, dtype=np.int64), np.zeros((0, 3))
        active = np.any(self.history != 0.0, axis=1)
        first, second = self._pair_ids(ids)
        first, second, history = first[active], second[active], self.history[active]
        # xi is i's displacement relative to j: it flips sign with the orientation.
        flip = first > second
        history = np.where(flip[:, None], -history, history)
        keys = _pair_keys(np.minimum(first, second), np.maximum(first, second))
        order = np.argsort(keys)
        return keys[order], history[order]

    def _restore_history(self, ids, old_keys, old_history):
        if len(old_keys) == 0 or self.pair_count == 0:
            return
        first, second = self._pair_ids(ids)
        keys = _pair_keys(np.minimum(first, second), np.maximum(first, second))
        position = np.searchsorted(old_keys, keys)
        position = np.minimum(position, len(old_keys) - 1)
        found = old_keys[position] == keys
        sign = np.where(first > second, -1.0, 1.0)
        self.history[found] = old_history[position[found]] * sign[found, None]


def _pair_keys(lower_ids, higher_ids):
    # Ids are below 2^31 per design (global particle counts); the key is unique.
    return lower_ids.astype(np.int64) * np.int64(2**31) + higher_ids.astype(np.int64)

"""Half Verlet list in CSR form over cell-sorted particles, with history carry-over.

Each pair within `skin` of touching is listed once (a half stencil of 13
neighbouring cells plus the own cell); the list stays valid until some
particle has moved more than skin/2 (checked in the drift kernel).  Tangential
history lives aligned with the list and is carried across a rebuild through
the sort permutation: the new pair (k, l) looks up the old pair of the same two
particles, flipping the sign when the old pair was stored the other way round.
"""
from __future__ import annotations

import numpy as np
from numba import njit

from pdemfem.neighbors.cells import cell_grid, cell_indices, cell_starts

# The 13 "forward" neighbour cells: each unordered pair of distinct cells is visited once.
_FORWARD_OFFSETS = np.array(
    [(dx, dy, dz) for dz in (-1, 0, 1) for dy in (-1, 0, 1) for dx in (-1, 0, 1)
     if dz > 0 or (dz == 0 and dy > 0) or (dz == 0 and dy == 0 and dx > 0)],
    dtype=np.int64,
)


@njit(cache=True)
def _fill_pairs(positions, radii, skin, cell_of, starts, dimensions, forward_offsets, offsets, partners):
    """Write partners row by row; returns the number of pairs (may exceed the capacity)."""
    count = positions.shape[0]
    capacity = partners.shape[0]
    nx, ny, nz = dimensions[0], dimensions[1], dimensions[2]
    written = 0
    for i in range(count):
        offsets[i] = written
        cell = cell_of[i]
        cx = cell % nx
        cy = (cell // nx) % ny
        cz = cell // (nx * ny)
        xi = positions[i, 0]
        yi = positions[i, 1]
        zi = positions[i, 2]
        reach = radii[i] + skin
        # Own cell: later particles only.
        for j in range(i + 1, starts[cell + 1]):
            dx = xi - positions[j, 0]
            dy = yi - positions[j, 1]
            dz = zi - positions[j, 2]
            cutoff = reach + radii[j]
            if dx * dx + dy * dy + dz * dz < cutoff * cutoff:
                if written < capacity:
                    partners[written] = j
                written += 1
        for k in range(forward_offsets.shape[0]):
            x = cx + forward_offsets[k, 0]
            y = cy + forward_offsets[k, 1]
            z = cz + forward_offsets[k, 2]
            if x < 0 or y < 0 or z < 0 or x >= nx or y >= ny or z >= nz:
                continue
            neighbour_cell = x + nx * (y + ny * z)
            for j in range(starts[neighbour_cell], starts[neighbour_cell + 1]):
                dx = xi - positions[j, 0]
                dy = yi - positions[j, 1]
                dz = zi - positions[j, 2]
                cutoff = reach + radii[j]
                if dx * dx + dy * dy + dz * dz < cutoff * cutoff:
                    if written < capacity:
                        partners[written] = j
                    written += 1
    offsets[count] = written
    return written


@njit(cache=True)
def _carry_history(new_offsets, new_partners, new_history, old_offsets, old_partners, old_history, old_index):
    """Copy each surviving pair's tangential spring into the new list (old_index: new -> old)."""
    for k in range(new_offsets.shape[0] - 1):
        a = old_index[k]
        for row in range(new_offsets[k], new_offsets[k + 1]):
            b = old_index[new_partners[row]]
            found = False
            for old_row in range(old_offsets[a], old_offsets[a + 1]):
                if old_partners[old_row] == b:
                    for axis in range(3):
                        new_history[row, axis] = old_history[old_row, axis]
                    found = True
                    break
            if not found:
                # Stored from b's side: xi is the relative displacement, so it flips sign.
                for old_row in range(old_offsets[b], old_offsets[b + 1]):
                    if old_partners[old_row] == a:
                        for axis in range(3):
                            new_history[row, axis] = -old_history[old_row, axis]
                        break


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
        if count == 0:
            self.__init__()
            return
        cell_size = 2.0 * float(state.radii.max()) + skin
        lower, cell_size, dimensions = cell_grid(state.positions, cell_size)
        cells = cell_indices(state.positions, lower, cell_size, dimensions)
        permutation = np.argsort(cells, kind="stable")
        state.reorder(permutation)
        cells = np.ascontiguousarray(cells[permutation])
        starts = cell_starts(cells, int(np.prod(dimensions)))
        offsets = np.empty(count + 1, dtype=np.int64)
        # One pass when the capacity guess (last size + margin) suffices, two otherwise.
        partners = np.empty(int(1.25 * self.pair_count) + 4 * count, dtype=np.int32)
        needed = _fill_pairs(state.positions, state.radii, skin, cells, starts, dimensions, _FORWARD_OFFSETS,
                             offsets, partners)
        if needed > len(partners):
            partners = np.empty(needed, dtype=np.int32)
            _fill_pairs(state.positions, state.radii, skin, cells, starts, dimensions, _FORWARD_OFFSETS,
                        offsets, partners)
        partners = partners[:needed].copy()
        history = np.zeros((needed, 3))
        if self.pair_count and len(self.offsets) == count + 1:
            _carry_history(offsets, partners, history, self.offsets, self.partners, self.history, permutation)
        self.offsets, self.partners, self.history = offsets, partners, history
        state.positions_at_build[:] = state.positions
        self.builds += 1

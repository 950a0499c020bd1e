"""Which rows of the particle state are owned, which are ghosts, and who sends what to whom.

    index_map = ParticleIndexMap(owned_count, neighbours, send_rows, send_shifts, receive_counts)
    index_map.owned_range                 # (0, owned): rows this rank integrates
    index_map.ghost_ranges[neighbour]     # [start, stop): the ghost rows `neighbour` sends
    index_map.send_rows[neighbour]        # owned rows sent to `neighbour` as its ghosts
    scatter = ForwardScatter(index_map, state, "ghost_step")   # buffers sized once per rebuild
    scatter.pack(state) ... MPI on scatter.send_buffers / receive_buffers ... scatter.unpack(state)

Like an index map of a finite element library (owned range, ghost range by owner, and
a named forward scatter owner -> ghosts), but for particles: the map is rebuilt at
every list rebuild (particles move), and between rebuilds the forward scatter of the
fields registered as `ghost_step` (pdemfem.particles.state) runs every step through
buffers allocated here, so the per-step ghost update allocates no arrays.
"""
from __future__ import annotations

import numpy as np
from numba import njit


class ParticleIndexMap:
    def __init__(self, owned_count: int, neighbours, send_rows: dict, send_shifts: dict, receive_counts: dict):
        self.owned_count = int(owned_count)
        self.neighbours = list(neighbours)
        self.send_rows = send_rows
        self.send_shifts = send_shifts
        self.receive_counts = receive_counts
        # Ghosts are appended neighbour by neighbour in this order (GhostExchange.plan_and_send).
        self.ghost_ranges = {}
        start = self.owned_count
        for neighbour in self.neighbours:
            self.ghost_ranges[neighbour] = (start, start + int(receive_counts[neighbour]))
            start += int(receive_counts[neighbour])
        self.ghost_count = start - self.owned_count

    @property
    def owned_range(self) -> tuple:
        return 0, self.owned_count


class ForwardScatter:
    """Owned rows -> their ghost copies for the fields with one registry flag, through buffers
    preallocated for the index map (one send and one receive matrix per neighbour)."""

    def __init__(self, index_map: ParticleIndexMap, state, flag: str):
        self.index_map = index_map
        self.registry_version = state.registry_version
        self.layout, self.width = state.layout(flag)
        self.shifted = [state.registry[name].periodic_shift for name, *_ in self.layout]
        self.send_buffers = {n: np.empty((len(index_map.send_rows[n]), self.width)) for n in index_map.neighbours}
        self.receive_buffers = {n: np.empty((int(index_map.receive_counts[n]), self.width))
                                for n in index_map.neighbours}

    def pack(self, state) -> None:
        """Copy the owned rows each neighbour receives into its send buffer (periodic shift added)."""
        index_map = self.index_map
        for neighbour in index_map.neighbours:
            buffer = self.send_buffers[neighbour]
            rows = index_map.send_rows[neighbour]
            shifts = index_map.send_shifts[neighbour]
            for (name, start, _, _, _), shifted in zip(self.layout, self.shifted):
                values = _as_matrix(state.array(name))
                if shifted:
                    _pack_shifted(values, rows, shifts, buffer, start)
                else:
                    _pack(values, rows, buffer, start)

    def unpack(self, state, buffers: dict) -> None:
        """Write each neighbour's received rows over its ghost range."""
        for neighbour in self.index_map.neighbours:
            first, _ = self.index_map.ghost_ranges[neighbour]
            buffer = buffers[neighbour]
            for name, start, *_ in self.layout:
                _unpack(buffer, start, _as_matrix(state.array(name)), first)


def _as_matrix(values: np.ndarray) -> np.ndarray:
    """(count, columns) view of a per-particle array (no copy; (count, 3) arrays pass as they are)."""
    return values if values.ndim == 2 else values.reshape(len(values), -1)


@njit(cache=True)
def _pack(values, rows, buffer, column):
    for k in range(rows.shape[0]):
        for c in range(values.shape[1]):
            buffer[k, column + c] = values[rows[k], c]


@njit(cache=True)
def _pack_shifted(values, rows, shifts, buffer, column):
    for k in range(rows.shape[0]):
        for c in range(values.shape[1]):
            buffer[k, column + c] = values[rows[k], c] + shifts[k, c]


@njit(cache=True)
def _unpack(buffer, column, values, first):
    for k in range(buffer.shape[0]):
        for c in range(values.shape[1]):
            values[first + k, c] = buffer[k, column + c]

"""Contact records: tangential springs keyed by the two particles' global ids.

A record is (owner id, partner id, xi_x, xi_y, xi_z), xi oriented for the owner
(its displacement relative to the partner).  Records are taken from the Verlet
list before a rebuild, travel with their owner when it migrates, and are looked
up again by (owner id, partner id) through an open-addressing hash table after
the new list is built.  Both directions are numba loops: O(pairs) each.
"""
from __future__ import annotations

import numpy as np
from numba import njit

RECORD_WIDTH = 5  # owner id, partner id, xi (3)
_EMPTY = -1


@njit(cache=True)
def collect_records(row_particles, offsets, partners, history, ids, owned_count):
    """Records of every spring in use, one per owned particle of the pair."""
    count = 0
    for r in range(row_particles.shape[0]):
        i = row_particles[r]
        for row in range(offsets[r], offsets[r + 1]):
            if history[row, 0] != 0.0 or history[row, 1] != 0.0 or history[row, 2] != 0.0:
                count += (i < owned_count) + (partners[row] < owned_count)
    records = np.empty((count, RECORD_WIDTH))
    written = 0
    for r in range(row_particles.shape[0]):
        i = row_particles[r]
        for row in range(offsets[r], offsets[r + 1]):
            if history[row, 0] == 0.0 and history[row, 1] == 0.0 and history[row, 2] == 0.0:
                continue
            j = partners[row]
            if i < owned_count:
                records[written, 0] = ids[i]
                records[written, 1] = ids[j]
                for axis in range(3):
                    records[written, 2 + axis] = history[row, axis]
                written += 1
            if j < owned_count:
                # xi is the first particle's displacement relative to the second: it flips.
                records[written, 0] = ids[j]
                records[written, 1] = ids[i]
                for axis in range(3):
                    records[written, 2 + axis] = -history[row, axis]
                written += 1
    return records


@njit(inline="always", cache=True)
def _slot(owner, partner, mask):
    key = owner * np.int64(2654435761) + partner * np.int64(40503)
    return (key ^ (key >> 17)) & mask


@njit(cache=True)
def restore_records(row_particles, offsets, partners, history, ids, owned_count, records):
    """Fill the new list's history from the records (pairs without a record start at zero)."""
    record_count = records.shape[0]
    if record_count == 0:
        return
    # Load factor at most 3/4: short probe chains, and the table stays small next to the list.
    size = 1
    while 3 * size < 4 * record_count:
        size *= 2
    mask = np.int64(size - 1)
    table = np.full(size, _EMPTY, dtype=np.int64)
    for k in range(record_count):
        owner = np.int64(records[k, 0])
        partner = np.int64(records[k, 1])
        slot = _slot(owner, partner, mask)
        while table[slot] != _EMPTY:
            slot = (slot + 1) & mask
        table[slot] = k
    for r in range(row_particles.shape[0]):
        i = row_particles[r]
        for row in range(offsets[r], offsets[r + 1]):
            j = partners[row]
            if i < owned_count:
                owner, partner, sign = ids[i], ids[j], 1.0
            else:
                owner, partner, sign = ids[j], ids[i], -1.0
            slot = _slot(owner, partner, mask)
            while table[slot] != _EMPTY:
                k = table[slot]
                if np.int64(records[k, 0]) == owner and np.int64(records[k, 1]) == partner:
                    for axis in range(3):
                        history[row, axis] = sign * records[k, 2 + axis]
                    break
                slot = (slot + 1) & mask

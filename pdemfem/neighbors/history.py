"""Contact records: contact history keyed by the two particles' global ids.

A record is (owner id, partner id, history...), the history oriented for the owner: its
columns (tangential spring, rolling spring, touching flag: pdemfem.contact.registry.history_layout)
are multiplied by `signs` (-1 for a spring, which flips with the pair's order) when the pair is
seen from the other particle.  Records are taken from the Verlet
list before a rebuild, travel with their owner when it migrates, and are looked
up again by (owner id, partner id) through an open-addressing hash table after
the new list is built.  Both directions are numba loops: O(pairs) each.
"""
from __future__ import annotations

import numpy as np
from numba import njit

RECORD_KEYS = 2  # owner id, partner id; then the history columns
_EMPTY = -1


@njit(inline="always", cache=True)
def _in_use(history, row):
    for column in range(history.shape[1]):
        if history[row, column] != 0.0:
            return True
    return False


@njit(cache=True)
def collect_records(row_particles, offsets, partners, history, ids, owned_count, signs):
    """Records of every contact with history in use, one per owned particle of the pair."""
    width = history.shape[1]
    count = 0
    for r in range(row_particles.shape[0]):
        i = row_particles[r]
        for row in range(offsets[r], offsets[r + 1]):
            if _in_use(history, row):
                count += (i < owned_count) + (partners[row] < owned_count)
    records = np.empty((count, RECORD_KEYS + width))
    written = 0
    for r in range(row_particles.shape[0]):
        i = row_particles[r]
        for row in range(offsets[r], offsets[r + 1]):
            if not _in_use(history, row):
                continue
            j = partners[row]
            if i < owned_count:
                records[written, 0] = ids[i]
                records[written, 1] = ids[j]
                for column in range(width):
                    records[written, RECORD_KEYS + column] = history[row, column]
                written += 1
            if j < owned_count:
                # The springs are the first particle's relative to the second: they flip.
                records[written, 0] = ids[j]
                records[written, 1] = ids[i]
                for column in range(width):
                    records[written, RECORD_KEYS + column] = signs[column] * history[row, column]
                written += 1
    return records


@njit(inline="always", cache=True)
def _slot(owner, partner, mask):
    key = owner * np.int64(2654435761) + partner * np.int64(40503)
    return (key ^ (key >> 17)) & mask


@njit(cache=True)
def restore_records(row_particles, offsets, partners, history, ids, owned_count, records, signs):
    """Fill the new list's history from the records (pairs without a record start at zero)."""
    width = history.shape[1]
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
            flipped = i >= owned_count
            if flipped:
                owner, partner = ids[j], ids[i]
            else:
                owner, partner = ids[i], ids[j]
            slot = _slot(owner, partner, mask)
            while table[slot] != _EMPTY:
                k = table[slot]
                if np.int64(records[k, 0]) == owner and np.int64(records[k, 1]) == partner:
                    for column in range(width):
                        value = records[k, RECORD_KEYS + column]
                        history[row, column] = signs[column] * value if flipped else value
                    break
                slot = (slot + 1) & mask

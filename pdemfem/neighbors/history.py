"""Contact records: contact history keyed by the two particles' global ids.

A record is (owner id, partner id, history...), the history oriented for the owner: its
columns (tangential spring, rolling spring, touching flag: pdemfem.contact.registry.history_layout)
are multiplied by `signs` (-1 for a spring, which flips with the pair's order) when the pair is
seen from the other particle.  Records are taken from the Verlet
list before a rebuild, travel with their owner when it migrates, and are looked
up again by (owner id, partner id) after the new list is built, among the few
records of either particle of the pair.  Both directions are numba loops: O(pairs) each.

Where particles migrate (several ranks, periodic images) a pair of two owned particles has a record
from each, because the two may be owned by different ranks after the rebuild.  Where nothing
migrates (one rank, no periodic boundary) one record per pair is enough (`one_per_pair`): the
records buffer, the largest array a settling bed holds (72 B a record), halves.

A particle's contact with plane wall w travels the same way, as the record (particle id,
-1 - w, history): the partner key is negative, so no pair ever matches it, and only the
particles near a wall hold one (a dense (particles, walls, columns) array held 160 B per
particle for five walls, most of it zeros).
"""
from __future__ import annotations

import numpy as np
from numba import njit

from pdemfem.neighbors.cells import cell_starts_of_unsorted

RECORD_KEYS = 2  # owner id, partner id; then the history columns


@njit(inline="always", cache=True)
def _in_use(history, row):
    for column in range(history.shape[1]):
        if history[row, column] != 0.0:
            return True
    return False


@njit(cache=True)
def collect_records_into(row_particles, offsets, partners, history, ids, owned_count, signs, records,
                         one_per_pair=False):
    """Write the records of every contact with history in use, one per owned particle of the pair (one per
    pair with `one_per_pair`), into the leading rows of `records` (as many as fit); returns how many there
    are (may exceed its rows)."""
    width = history.shape[1]
    capacity = records.shape[0]
    written = 0
    for r in range(row_particles.shape[0]):
        i = row_particles[r]
        i_owned = i < owned_count
        for row in range(offsets[r], offsets[r + 1]):
            if not _in_use(history, row):
                continue
            j = partners[row]
            if i_owned:
                if written < capacity:
                    records[written, 0] = ids[i]
                    records[written, 1] = ids[j]
                    for column in range(width):
                        records[written, RECORD_KEYS + column] = history[row, column]
                written += 1
            if j < owned_count and not (one_per_pair and i_owned):
                if written < capacity:
                    # The springs are the first particle's relative to the second: they flip.
                    records[written, 0] = ids[j]
                    records[written, 1] = ids[i]
                    for column in range(width):
                        records[written, RECORD_KEYS + column] = signs[column] * history[row, column]
                written += 1
    return written


@njit(cache=True)
def collect_records(row_particles, offsets, partners, history, ids, owned_count, signs, one_per_pair=False):
    """Records of every contact with history in use, one per owned particle of the pair (one per pair with
    `one_per_pair`), as a new array."""
    width = history.shape[1]
    count = collect_records_into(row_particles, offsets, partners, history, ids, owned_count, signs,
                                 np.empty((0, RECORD_KEYS + width)), one_per_pair)
    records = np.empty((count, RECORD_KEYS + width))
    collect_records_into(row_particles, offsets, partners, history, ids, owned_count, signs, records, one_per_pair)
    return records


@njit(cache=True)
def _owned_rows_of(records, ids, owned_count):
    """The owned row holding each record's owner id (-1: not owned on this rank).  Ids are unique among
    the owned rows; a table indexed by id when they are dense enough, a binary search otherwise."""
    rows = np.full(records.shape[0], -1, dtype=np.int64)
    if owned_count == 0:
        return rows
    smallest = ids[0]
    largest = ids[0]
    for i in range(owned_count):
        smallest = min(smallest, ids[i])
        largest = max(largest, ids[i])
    span = largest - smallest + 1
    if span <= 4 * owned_count + 1024:
        row_of_id = np.full(span, -1, dtype=np.int64)
        for i in range(owned_count):
            row_of_id[ids[i] - smallest] = i
        for k in range(records.shape[0]):
            offset = np.int64(records[k, 0]) - smallest
            if 0 <= offset < span:
                rows[k] = row_of_id[offset]
    else:
        order = np.argsort(ids[:owned_count])
        sorted_ids = ids[:owned_count][order]
        for k in range(records.shape[0]):
            owner = np.int64(records[k, 0])
            position = np.searchsorted(sorted_ids, owner)
            if position < owned_count and sorted_ids[position] == owner:
                rows[k] = order[position]
    return rows


@njit(cache=True)
def restore_records(row_particles, offsets, partners, history, ids, owned_count, records, signs):
    """Fill the new list's history from the records (pairs without a record start at zero).

    A pair's record is looked up among i's records (partner j), then, when j is owned, among j's (partner
    i; the springs flip): records collected one per pair hold either.  A ghost i has no records here, so
    only j's are looked up.  The records are grouped by their owner's row (a counting sort, stable: of two
    records of one particle for one partner the first wins), so each listed pair scans the few records of
    one or two particles, in about the order of the list (a hash table over all records cost a cache miss
    or two per listed pair)."""
    width = history.shape[1]
    record_count = records.shape[0]
    if record_count == 0:
        return
    owner_rows = _owned_rows_of(records, ids, owned_count)
    starts = np.zeros(owned_count + 1, dtype=np.int64)
    for k in range(record_count):
        if owner_rows[k] >= 0:
            starts[owner_rows[k] + 1] += 1
    for i in range(owned_count):
        starts[i + 1] += starts[i]
    next_slot = starts[:-1].copy()
    record_of_slot = np.empty(starts[owned_count], dtype=np.int64)
    partner_of_slot = np.empty(starts[owned_count], dtype=np.int64)
    for k in range(record_count):
        owner_row = owner_rows[k]
        if owner_row >= 0:
            slot = next_slot[owner_row]
            record_of_slot[slot] = k
            partner_of_slot[slot] = np.int64(records[k, 1])
            next_slot[owner_row] = slot + 1
    for r in range(row_particles.shape[0]):
        i = row_particles[r]
        i_owned = i < owned_count
        for row in range(offsets[r], offsets[r + 1]):
            j = partners[row]
            k = -1
            if i_owned:
                k = _record_of(starts, partner_of_slot, record_of_slot, i, ids[j])
            flipped = k < 0
            if flipped and j < owned_count:
                k = _record_of(starts, partner_of_slot, record_of_slot, j, ids[i])
            if k >= 0:
                for column in range(width):
                    value = records[k, RECORD_KEYS + column]
                    history[row, column] = signs[column] * value if flipped else value


@njit(inline="always", cache=True)
def _record_of(starts, partner_of_slot, record_of_slot, owner_row, partner):
    """The first record of the particle at owned row `owner_row` for `partner` (an id), -1: none."""
    for slot in range(starts[owner_row], starts[owner_row + 1]):
        if partner_of_slot[slot] == partner:
            return record_of_slot[slot]
    return -1


@njit(cache=True)
def collect_wall_records_into(candidate_particles, candidate_walls, candidate_history, ids, records, start):
    """Write the records (particle id, -1 - wall, history) of the plane-wall contacts with history in use into
    `records` from row `start` on (as many as fit); returns start + how many there are."""
    width = candidate_history.shape[1]
    capacity = records.shape[0]
    written = start
    for candidate in range(candidate_particles.shape[0]):
        if not _in_use(candidate_history, candidate):
            continue
        if written < capacity:
            records[written, 0] = ids[candidate_particles[candidate]]
            records[written, 1] = -1 - candidate_walls[candidate]
            for column in range(width):
                records[written, RECORD_KEYS + column] = candidate_history[candidate, column]
        written += 1
    return written


@njit(cache=True)
def restore_wall_records(candidate_particles, candidate_walls, candidate_history, ids, owned_count, records):
    """Fill the plane-wall candidates' history from the records with a negative partner key (candidates
    without one keep their zeros).  The candidates come in ascending particle row (pdemfem.walls.plane), so
    a particle's are one run and each record scans only its owner's few."""
    width = candidate_history.shape[1]
    wall_rows = 0
    for k in range(records.shape[0]):
        if records[k, 1] < 0.0:
            wall_rows += 1
    if wall_rows == 0 or candidate_particles.shape[0] == 0:
        return
    wall_records = np.empty((wall_rows, records.shape[1]))
    wall_rows = 0
    for k in range(records.shape[0]):
        if records[k, 1] < 0.0:
            wall_records[wall_rows] = records[k]
            wall_rows += 1
    owner_rows = _owned_rows_of(wall_records, ids, owned_count)
    # Where each particle row's candidates start: the counting sort's offsets, particle rows as the keys.
    starts = cell_starts_of_unsorted(candidate_particles, owned_count)
    for k in range(wall_rows):
        row = owner_rows[k]
        if row < 0:
            continue
        wall = -1 - np.int64(wall_records[k, 1])
        for candidate in range(starts[row], starts[row + 1]):
            if candidate_walls[candidate] == wall:
                for column in range(width):
                    candidate_history[candidate, column] = wall_records[k, RECORD_KEYS + column]
                break

"""Moving particles between ranks with buffer-based mpi4py calls.

Migration (at list rebuilds): particles whose position now lies in another
rank's box move there with every migrating field and their contact records,
through Alltoall (counts) + Alltoallv (one float64 matrix).  Ghosts: copies of
owned particles within the ghost cutoff of a neighbour's box (and of periodic
images) are sent once in full at a rebuild and refreshed every step with
positions and velocities only, point to point with the neighbour ranks.
"""
from __future__ import annotations

import itertools

import numpy as np
from mpi4py import MPI
from numba import njit

from pdemfem.kept_rows import KeptRows
from pdemfem.parallel.decomposition import rows_near_box
from pdemfem.parallel.index_map import ForwardScatter, ParticleIndexMap

# Fixed tags are safe: the particle system talks on a private duplicate of the user's communicator
# (pdemfem.parallel.api_safety), so no message of the user's code can match them.
_GHOST_TAG = 71  # counts on 71, rows on 72
_GHOST_UPDATE_TAG = 81  # the per-step update's rows (counts known)


def _alltoallv_rows(comm, rows: np.ndarray, destinations: np.ndarray, width: int) -> np.ndarray:
    """Send row k of `rows` to rank destinations[k]; returns the rows received (by source rank)."""
    size = comm.size
    order = np.argsort(destinations, kind="stable")
    send = np.ascontiguousarray(rows[order]).reshape(-1)
    send_counts = np.bincount(destinations, minlength=size).astype(np.int64)
    receive_counts = np.empty(size, dtype=np.int64)
    comm.Alltoall(send_counts, receive_counts)
    received = np.empty((int(receive_counts.sum()), width))
    send_items = (send_counts * width).astype(np.int64)
    receive_items = (receive_counts * width).astype(np.int64)
    send_displacements = np.concatenate([[0], np.cumsum(send_items)[:-1]]).astype(np.int64)
    receive_displacements = np.concatenate([[0], np.cumsum(receive_items)[:-1]]).astype(np.int64)
    comm.Alltoallv([send, (send_items, send_displacements), MPI.DOUBLE],
                   [received.reshape(-1), (receive_items, receive_displacements), MPI.DOUBLE])
    return received


def route_records_to_owner_share(comm, ids: np.ndarray, records: np.ndarray) -> np.ndarray:
    """Send each record (owner id first) to the rank whose id-sorted, contiguous share of the
    particles (`ids`, as a checkpoint is read back) holds its owner id."""
    first_ids = np.array(comm.allgather(int(ids[0]) if len(ids) else None), dtype=object)
    ranks = np.array([r for r, value in enumerate(first_ids) if value is not None], dtype=np.int64)
    starts = np.array([first_ids[r] for r in ranks], dtype=np.int64)
    owners = records[:, 0].astype(np.int64) if len(records) else np.zeros(0, np.int64)
    if len(ranks) == 0:
        destinations = np.zeros(len(owners), dtype=np.int64)
    else:
        destinations = ranks[np.maximum(np.searchsorted(starts, owners, side="right") - 1, 0)]
    return _alltoallv_rows(comm, np.ascontiguousarray(records, dtype=np.float64), destinations, records.shape[1])


def allgather_rows(comm, rows: np.ndarray, width: int) -> np.ndarray:
    """Every rank's float rows (n_r, width), concatenated in rank order, on every rank."""
    rows = np.ascontiguousarray(rows, dtype=np.float64).reshape(-1, width)
    if comm.size == 1:
        return rows.copy()
    counts = np.zeros(comm.size, dtype=np.int64)
    comm.Allgather(np.array([rows.size], dtype=np.int64), counts)
    gathered = np.empty(int(counts.sum()), dtype=np.float64)
    displacements = np.concatenate([[0], np.cumsum(counts)[:-1]])
    comm.Allgatherv(rows.ravel(), [gathered, counts, displacements, MPI.DOUBLE])
    return gathered.reshape(-1, width)


def migrate(comm, state, destinations: np.ndarray, records: np.ndarray,
            kept_rows: KeptRows | None = None, records_buffer: KeptRows | None = None) -> np.ndarray:
    """Send owned particles (ghosts already dropped) to their destination ranks.

    `records` are contact-history rows (owner id, partner id, xi_x, xi_y, xi_z)
    of owned particles; they travel with their owner.  Returns this rank's records (in `kept_rows`' buffer
    when given and large enough: valid until its next use).  When `records` are the leading rows of
    `records_buffer` (the list's collected records), the records kept are moved up in place and those that
    arrive written after them: the few that leave cost a copy of the rows after the first of them, not of all.
    """
    rank = comm.rank
    layout, width = state.migrating_layout()
    leaving = np.flatnonzero(destinations != rank)
    packed = state.pack_rows(leaving, layout, width)
    # Records follow their owner.  Only the leaving particles' records move: look each record's
    # owner up among the (few) leaving ids, not among all owned ids (a random-access search
    # over every owned particle cost ~75 ms per rebuild at 100k particles and 400k records).
    leaving_ids = state.ids[leaving]
    order = np.argsort(leaving_ids)
    kept_records, moving_records, record_destinations = records, records[:0], np.zeros(0, dtype=np.int64)
    in_place = records_buffer is not None and records_buffer.leads(records)
    if in_place:
        kept_records = records_buffer.rows  # those that arrive go after the kept ones, in place
    if len(records) and len(leaving):
        # One pass splits the records into kept and moving rows, with room after the kept ones for those that
        # arrive: numpy's search, masks and concatenation took 0.57 ms per rebuild at 21,000 records.  In place
        # when the records lead a buffer of ours: copying every kept record took 0.36-0.55 ms of a 2-rank
        # rebuild of the 28k settle bed, where ~11 particles leave (near the cut: their records come last).
        if not in_place:
            room = len(records) + len(records) // 8 + 64
            kept_records = (np.empty((room, records.shape[1])) if kept_rows is None
                            else kept_rows.at_least(room, records.shape[1]))
        moving_records = np.empty_like(records)
        record_destinations = np.empty(len(records), dtype=np.int64)
        kept, moving = _split_records(records, leaving_ids[order], destinations[leaving][order].astype(np.int64),
                                      kept_records, moving_records, record_destinations, in_place)
        moving_records, record_destinations = moving_records[:moving], record_destinations[:moving]
    else:
        kept = len(records)
    if len(leaving):  # most rebuilds move few particles, many none
        state.remove(leaving)
    incoming = _alltoallv_rows(comm, packed, destinations[leaving].astype(np.int64), width)
    state.append_rows(incoming, layout, as_ghosts=False)
    incoming_records = _alltoallv_rows(comm, moving_records, record_destinations, records.shape[1])
    arrived = len(incoming_records)
    if kept_records is not records and kept + arrived <= len(kept_records):
        kept_records[kept:kept + arrived] = incoming_records
        return kept_records[:kept + arrived]
    return np.concatenate([kept_records[:kept], incoming_records]) if arrived else kept_records[:kept]


@njit(cache=True)
def _split_records(records, sorted_leaving_ids, leaving_destinations, kept_records, moving_records,
                   moving_destinations, in_place):
    """Copy each record (owner id first) to kept_records, or, when its owner is among the leaving ids (sorted),
    to moving_records with the owner's destination.  Returns (kept, moving) counts.  `in_place`: kept_records
    starts where records start (record k is read before any row from k on is written, so this is safe), and a
    kept record already at its place is not copied."""
    kept = 0
    moving = 0
    columns = records.shape[1]
    leaving = sorted_leaving_ids.shape[0]
    smallest, largest = sorted_leaving_ids[0], sorted_leaving_ids[leaving - 1]
    # The destination by id, from a table over the leaving ids' span when it is small against the records (a
    # binary search per record cost 17 ns of the 19 a record took), else by binary search.
    span = largest - smallest + 1
    by_table = span <= 4 * records.shape[0] + 1024
    destination_of_id = np.full(span if by_table else 0, -1, dtype=np.int64)
    if by_table:
        for position in range(leaving):
            destination_of_id[sorted_leaving_ids[position] - smallest] = leaving_destinations[position]
    for k in range(records.shape[0]):
        owner = np.int64(records[k, 0])
        destination = -1
        if smallest <= owner <= largest:
            if by_table:
                destination = destination_of_id[owner - smallest]
            else:
                position = np.searchsorted(sorted_leaving_ids, owner)
                if sorted_leaving_ids[position] == owner:
                    destination = leaving_destinations[position]
        # Rows are copied column by column (a row slice assignment made a view per record).
        if destination >= 0:
            for column in range(columns):
                moving_records[moving, column] = records[k, column]
            moving_destinations[moving] = destination
            moving += 1
        else:
            if not in_place or kept != k:
                for column in range(columns):
                    kept_records[kept, column] = records[k, column]
            kept += 1
    return kept, moving


class GhostExchange:
    """Which owned particles are sent as ghosts to which neighbour (a ParticleIndexMap, chosen at every
    rebuild), and the exchanges: in full at a rebuild, the `ghost_step` fields every step."""

    def __init__(self, comm, decomposition, cutoff: float, periodic_lengths: np.ndarray):
        self.comm = comm
        self.cutoff = float(cutoff)
        rank = comm.rank
        boxes = decomposition.boxes
        shifts = [np.array(combination, dtype=float) * periodic_lengths
                  for combination in itertools.product(*[(-1, 0, 1) if length > 0 else (0,)
                                                          for length in periodic_lengths])]
        # (neighbour rank, shift) pairs whose box is within the cutoff of our shifted box.
        my_lower, my_upper = boxes[rank]
        self.targets = []
        for other in range(comm.size):
            for shift in shifts:
                if other == rank and not np.any(shift):
                    continue
                if _box_gap(my_lower + shift, my_upper + shift, boxes[other, 0], boxes[other, 1]) < self.cutoff:
                    self.targets.append((other, shift, boxes[other, 0], boxes[other, 1]))
        self.neighbours = sorted({target[0] for target in self.targets})
        self.index_map = None
        self.step_scatter = None
        self._receives = []
        self._sends = []
        # The per-step update's messages as persistent requests on the scatter's blocks and the ghost rows, made
        # once per rebuild and started every step (posting six messages afresh cost 10-17 us a step on 2 ranks).
        self._update_receives = []
        self._update_sends = []

    def select(self, positions: np.ndarray) -> list:
        """Per target (neighbour and periodic shift), the rows of these owned positions within the cutoff of its
        box, ascending: the ghosts to send.  A rebuild selects once (ParticleSystem._sort_owned, which puts them
        last) and hands the selection, renumbered through its reorder, to plan_and_send."""
        return [rows_near_box(positions, np.asarray(shift, dtype=np.float64), lower, upper, self.cutoff)
                for _, shift, lower, upper in self.targets]

    @staticmethod
    def sent_rows_mask(selection: list, count: int) -> np.ndarray:
        """Which of `count` owned rows a selection sends to some neighbour (the particles with pairs across a
        cut)."""
        sent = np.zeros(count, dtype=bool)
        for rows in selection:
            sent[rows] = True
        return sent

    @staticmethod
    def renumber(selection: list, permutation: np.ndarray) -> list:
        """The selection after state.reorder(permutation) (new row k was row permutation[k]), ascending: what
        select gives on the reordered positions."""
        new_row_of = np.empty(len(permutation), dtype=np.int64)
        new_row_of[permutation] = np.arange(len(permutation))
        return [np.sort(new_row_of[rows]) for rows in selection]

    def plan_and_send(self, state, selection: list | None = None) -> None:
        """Send the selected ghosts (`select` on the owned positions, made here when not given) in full, append
        those received, and size the per-step scatter's buffers for the new index map."""
        self.complete_messages()
        owned = state.owned_count
        if selection is None:
            selection = self.select(state.positions[:owned])
        rows = {neighbour: [] for neighbour in self.neighbours}
        shifts = {neighbour: [] for neighbour in self.neighbours}
        for (other, shift, _, _), near in zip(self.targets, selection):
            rows[other].append(near)
            shifts[other].append(np.tile(shift, (len(near), 1)))
        send_rows = {n: np.concatenate(rows[n]).astype(np.int64) if rows[n] else np.zeros(0, np.int64)
                     for n in self.neighbours}
        send_shifts = {n: np.ascontiguousarray(np.concatenate(shifts[n])) if shifts[n] else np.zeros((0, 3))
                       for n in self.neighbours}
        layout, width = state.ghost_layout()
        outgoing = {}
        for neighbour in self.neighbours:
            packed = state.pack_rows(send_rows[neighbour], layout, width)
            for name, start, columns, _, _ in layout:
                if state.registry[name].periodic_shift:
                    packed[:, start:start + columns] += send_shifts[neighbour]
            outgoing[neighbour] = packed
        received = self._exchange(outgoing, width, _GHOST_TAG)
        receive_counts = {}
        for neighbour in self.neighbours:
            receive_counts[neighbour] = len(received[neighbour])
            if len(received[neighbour]):
                state.append_rows(received[neighbour], layout, as_ghosts=True)
        self.index_map = ParticleIndexMap(owned, self.neighbours, send_rows, send_shifts, receive_counts)
        self._make_step_scatter(state)

    def late_rows(self, state) -> np.ndarray | None:
        """A mask over the state's rows of the ghosts and the owned particles sent as ghosts (the rows that can
        hold a pair with a ghost), or None when there are none."""
        if self.index_map is None or (not state.ghost_count and not any(len(rows) for rows in
                                                                        self.index_map.send_rows.values())):
            return None
        late = np.zeros(state.count, dtype=bool)
        late[state.owned_count:] = True
        for rows in self.index_map.send_rows.values():
            late[rows] = True
        return late

    def _make_step_scatter(self, state) -> None:
        """The per-step scatter for the current index map and state arrays, and its persistent requests."""
        self._free_update_requests()
        scatter = self.step_scatter = ForwardScatter(self.index_map, state, "ghost_step")
        comm, rank = self.comm, self.comm.rank
        # Messages of one source and tag match in the order they were posted: field by field.
        self._update_receives = [comm.Recv_init(rows, source=n, tag=_GHOST_UPDATE_TAG)
                                 for n in self.neighbours if n != rank for rows in scatter.ghost_rows(state, n)]
        self._update_sends = [comm.Send_init(block, dest=n, tag=_GHOST_UPDATE_TAG)
                              for n in self.neighbours if n != rank for block in scatter.send_blocks[n]]

    def _free_update_requests(self) -> None:
        """Free the persistent requests (inactive: complete_messages ran before)."""
        for request in self._update_receives + self._update_sends:
            request.Free()
        self._update_receives, self._update_sends = [], []

    def update(self, state) -> None:
        """Refresh the ghosts' `ghost_step` fields (every step between rebuilds): owned rows packed into
        the preallocated send blocks, received straight into the ghost rows."""
        self.start_update(state)
        self.finish_update(state)

    def start_update(self, state) -> None:
        """The first half of update: pack and post the messages.  Work that reads no ghost (the pairs of two
        owned particles) can run before finish_update, while they travel."""
        if not self.neighbours:
            return
        self.complete_messages()
        if not self.step_scatter.bound_to(state):  # a field was registered (or an array replaced) since the rebuild
            self._make_step_scatter(state)
        self.step_scatter.pack(state)
        # Receives first, then sends, as the requests were made.
        if self._update_receives:
            MPI.Prequest.Startall(self._update_receives)
            MPI.Prequest.Startall(self._update_sends)
        self._receives = self._update_receives
        self._sends = self._update_sends

    def finish_update(self, state) -> None:
        """The second half of update: wait for the neighbours' rows and write them over the ghost rows.  The
        sends are completed later (complete_messages: at the next update or rebuild); waiting for them here
        would wait until every neighbour has reached its own finish_update (a large message is read by its
        receiver), a rendezvous the receives do not need."""
        if not self.neighbours:
            return
        MPI.Request.Waitall(self._receives)
        self._receives = []
        self.step_scatter.copy_own(state, self.comm.rank)

    def close(self) -> None:
        """Complete the messages in flight and free the persistent requests (the exchange is being replaced)."""
        self.complete_messages()
        self._free_update_requests()

    def complete_messages(self) -> None:
        """Wait for the last update's sends (their buffers are reused, or dropped with this exchange), and for
        its receives if an error between start_update and finish_update left them posted (a receive left
        pending would take the next update's rows)."""
        if self._sends or self._receives:
            MPI.Request.Waitall(self._receives + self._sends)
            self._receives, self._sends = [], []

    def _exchange(self, outgoing: dict, width: int, tag: int) -> dict:
        """Point-to-point rows to every neighbour, their counts first (tag, then tag + 1); the own rank's rows
        (periodic images) are copied."""
        comm, rank = self.comm, self.comm.rank
        requests = []
        count_buffers = {n: np.empty(1, dtype=np.int64) for n in self.neighbours}
        for neighbour in self.neighbours:
            if neighbour != rank:
                requests.append(comm.Irecv(count_buffers[neighbour], source=neighbour, tag=tag))
        send_counts = {n: np.array([len(outgoing[n])], dtype=np.int64) for n in self.neighbours}
        for neighbour in self.neighbours:
            if neighbour != rank:
                requests.append(comm.Isend(send_counts[neighbour], dest=neighbour, tag=tag))
        MPI.Request.Waitall(requests)
        received = {}
        requests = []
        for neighbour in self.neighbours:
            if neighbour == rank:
                received[neighbour] = outgoing[neighbour].copy()
                continue
            received[neighbour] = np.empty((int(count_buffers[neighbour][0]), width))
            requests.append(comm.Irecv(received[neighbour], source=neighbour, tag=tag + 1))
        for neighbour in self.neighbours:
            if neighbour != rank:
                requests.append(comm.Isend(outgoing[neighbour], dest=neighbour, tag=tag + 1))
        MPI.Request.Waitall(requests)
        return received


def _box_gap(lower_a, upper_a, lower_b, upper_b) -> float:
    with np.errstate(invalid="ignore"):
        gaps = np.maximum(0.0, np.maximum(lower_b - upper_a, lower_a - upper_b))
    gaps = np.where(np.isfinite(gaps), gaps, 0.0)
    return float(np.sqrt(np.sum(gaps * gaps)))

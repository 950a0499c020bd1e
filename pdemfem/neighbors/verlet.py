"""Half Verlet list in CSR form over owned particles and ghosts, with history carry-over.

Each pair within `skin` of touching that involves at least one owned particle is
listed once (a half stencil of 13 neighbouring cells plus the own cell).  Rows
follow the cell order (`row_particles[r]` is the particle of row r), so the
force loop walks memory in space-filling order.  The list stays valid until
some particle has moved more than skin/2 (checked in the drift kernel).

Tangential history lives aligned with the list.  Across a rebuild (and a
migration between ranks) it travels as *contact records* (owner id, partner
id, xi oriented for the owner), one per owned particle in a contact, and is
looked up again by the two global ids, so no history is lost to a re-sort,
a migration or a change of rank count.  The plane walls' contacts travel in the
same records (partner key -1 - wall, pdemfem.neighbors.history).
"""
from __future__ import annotations

import numpy as np
from numba import njit

from pdemfem import state_dict as kinds
from pdemfem.kept_rows import SLACK, KeptRows
from pdemfem.neighbors.cells import cell_grid, cell_indices, sort_by_cell
from pdemfem.neighbors.history import RECORD_KEYS, collect_records_into, collect_wall_records_into, restore_records

# The half stencil as runs of cells consecutive in the grid (x fastest): the own cell (later rows only) and
# its +x neighbour; the row (dy, dz) = (+1, 0) from x-1 to x+1; the three rows dz = +1, dy = -1, 0, +1.
# Each unordered pair of distinct cells is visited once, the 13 forward cells in the order a cell-by-cell
# walk (dz, then dy, then dx) takes, and a run is one range of the cell-sorted rows: 5 ranges per
# particle instead of 14 cells.
_FORWARD_ROWS = np.array([(1, 0), (-1, 1), (0, 1), (1, 1)], dtype=np.int64)  # (dy, dz) of the full x-runs


@njit(cache=True)
def _fill_pairs(sorted_positions, sorted_radii, skin, owned_count, order, sorted_cells, starts, dimensions,
                forward_rows, sorted_materials, cohesion_reach, cohesive, row_sequence, offsets, partners):
    """Write partners row by row (row r = particle order[p], p = row_sequence[r], or p = r when row_sequence
    is empty); returns the pair count (may exceed capacity).

    The particles' positions, radii and materials come in cell order (at p): the stencil's candidates then
    sit side by side in memory instead of being gathered through `order`.  Without cohesive pairs
    (`cohesive` False) the cutoff needs no look-up in cohesion_reach."""
    count = order.shape[0]
    capacity = partners.shape[0]
    nx, ny, nz = dimensions[0], dimensions[1], dimensions[2]
    sequenced = row_sequence.shape[0] > 0
    written = 0
    for r in range(count):
        p = row_sequence[r] if sequenced else r
        offsets[r] = written
        i_is_ghost = order[p] >= owned_count
        cell = sorted_cells[p]
        cx = cell % nx
        cy = (cell // nx) % ny
        cz = cell // (nx * ny)
        xi = sorted_positions[p, 0]
        yi = sorted_positions[p, 1]
        zi = sorted_positions[p, 2]
        reach = sorted_radii[p] + skin
        material_i = sorted_materials[p]
        first_x = cx - 1 if cx > 0 else cx
        last_x = cx + 1 if cx + 1 < nx else cx
        for run in range(forward_rows.shape[0] + 1):
            if run == 0:
                # The own cell's later rows, then the +x cell.
                first = p + 1
                last = starts[cell - cx + last_x + 1]
            else:
                y = cy + forward_rows[run - 1, 0]
                z = cz + forward_rows[run - 1, 1]
                if y < 0 or z < 0 or y >= ny or z >= nz:
                    continue
                row_start = nx * (y + ny * z)
                first = starts[row_start + first_x]
                last = starts[row_start + last_x + 1]
            for q in range(first, last):
                dx = xi - sorted_positions[q, 0]
                dy = yi - sorted_positions[q, 1]
                dz = zi - sorted_positions[q, 2]
                cutoff = reach + sorted_radii[q]
                if cohesive:
                    # A cohesive pair interacts until its pull-off distance beyond touching.
                    cutoff += cohesion_reach[material_i, sorted_materials[q]]
                j = order[q]
                # Every candidate is written and the count advances only for a pair (the next candidate
                # overwrites a miss): a fifth of the candidates pass, at no pattern a predictor can learn, and
                # the branch on the test that this replaces cost 30 % of the build (3.9 -> 2.7 ms, same list).
                if written < capacity:
                    partners[written] = j
                written += (dx * dx + dy * dy + dz * dz < cutoff * cutoff) and not (i_is_ghost and j >= owned_count)
    offsets[count] = written
    return written


@njit(cache=True)
def _owned_partners_first(order, offsets, partners, owned_count, interior_ends, first_row):
    """Reorder each row's partners, owned ones first (stable), and set interior_ends[p] to the end of the
    owned ones: [offsets[p], interior_ends[p]) are the row's pairs of two owned particles, which need no
    ghost's current state, [interior_ends[p], offsets[p + 1]) its pairs with a ghost.  A ghost's row holds
    only pairs with a ghost (its own).  The rows before `first_row` hold no pair with a ghost (VerletList.build's
    early rows) and their partners are not read.  Returns the number of rows with pairs with a ghost."""
    for p in range(first_row):
        interior_ends[p] = offsets[p + 1]
    longest = 0
    for p in range(first_row, order.shape[0]):
        longest = max(longest, offsets[p + 1] - offsets[p])
    with_ghosts = np.empty(longest, dtype=partners.dtype)
    boundary_rows = 0
    for p in range(first_row, order.shape[0]):
        start = offsets[p]
        end = offsets[p + 1]
        if order[p] >= owned_count:
            interior_ends[p] = start
        else:
            written = start
            ghosts = 0
            for slot in range(start, end):
                j = partners[slot]
                if j < owned_count:
                    partners[written] = j
                    written += 1
                else:
                    with_ghosts[ghosts] = j
                    ghosts += 1
            for k in range(ghosts):
                partners[written + k] = with_ghosts[k]
            interior_ends[p] = written
        if interior_ends[p] < end:
            boundary_rows += 1
    return boundary_rows


_NO_SEQUENCE = np.zeros(0, dtype=np.int64)  # rows in cell order (_fill_pairs)


class VerletList:
    """row_particles (rows), offsets (rows+1), partners (int32), history (pairs, width) aligned with partners
    (partners and history are the leading rows of buffers reused by the next build); `interior` and
    `boundary`: the (row particles, pair starts, pair ends) of the pairs without and with a ghost
    (`interior_pair_count` pairs of two owned particles, the rest with a ghost).

    `history_signs` (one per history column: -1 for a spring, +1 for a symmetric flag) sets the
    history width (0: no history, e.g. frictionless spheres); `cohesion_reach[a, b]` [m] widens
    the cutoff of cohesive material pairs beyond touching (pdemfem.contact.tables)."""

    def __init__(self, history_signs=(-1.0, -1.0, -1.0), cohesion_reach=None):
        self.history_signs = np.asarray(history_signs, dtype=np.float64).reshape(-1)
        self.cohesion_reach = (np.zeros((1, 1)) if cohesion_reach is None
                               else np.ascontiguousarray(cohesion_reach, dtype=np.float64))
        # What `partners` and `history` are views of (build).
        self._partner_buffer = np.zeros(0, dtype=np.int32)
        self._history_buffer = np.zeros((0, len(self.history_signs)))
        self._records = KeptRows(RECORD_KEYS + len(self.history_signs))
        self._sorted_positions = KeptRows(3)
        self._clear()

    def _clear(self):
        self.row_particles = np.zeros(0, dtype=np.int64)
        self.offsets = np.zeros(1, dtype=np.int64)
        self.partners = np.zeros(0, dtype=np.int32)
        self.history = np.zeros((0, len(self.history_signs)))
        self.interior = self.boundary = (self.row_particles, self.offsets[:0], self.offsets[:0])
        self.interior_pair_count = 0  # pairs of two owned particles (the others have a ghost)
        self.builds = 0
        # Contact records loaded from a checkpoint: used by the next build instead of this list's.
        self._loaded_records = None

    @property
    def largest_reach(self) -> float:
        return float(self.cohesion_reach.max()) if self.cohesion_reach.size else 0.0

    @property
    def record_buffer(self) -> KeptRows:
        """The buffer contact_records returns the leading rows of (free to reuse once the records are read back:
        migration moves them up in place)."""
        return self._records

    @property
    def pair_count(self) -> int:
        return len(self.partners)

    def pair_rows(self):
        """(first particle, second particle) of every listed pair."""
        return np.repeat(self.row_particles, np.diff(self.offsets)), self.partners.astype(np.int64)

    def build(self, state, skin: float, records: np.ndarray, late_rows=None) -> None:
        """Rebuild over owned particles and ghosts; restore history from contact records.

        `late_rows` (a mask over the state's rows, or None): the particles whose rows come after all others
        (each part in cell order), so that their pairs are one block of the list: the ghosts and the owned
        particles sent as ghosts, whose rows hold every pair with a ghost (ParticleSystem._rebuild)."""
        count = state.count
        if count == 0:
            self._clear()
            self.builds = 1
            return
        cell_size = 2.0 * float(state.radii.max()) + skin + self.largest_reach
        lower, cell_size, dimensions = cell_grid(state.positions, cell_size)
        cells = cell_indices(state.positions, lower, cell_size, dimensions)
        order, starts = sort_by_cell(cells, int(np.prod(dimensions)))
        sorted_cells = cells[order]
        offsets = np.empty(count + 1, dtype=np.int64)
        sorted_materials = (state.material_index[order] if self.cohesion_reach.shape[0] > 1
                            else np.zeros(count, np.int32))
        # The sorted positions into a buffer kept from build to build (a fresh 3-vector per particle is
        # mapped afresh by malloc and page-faulted at every rebuild, pdemfem.runtime.fix_malloc).
        sorted_positions = self._sorted_positions.at_least(count, 3)[:count]
        np.take(state.positions, order, axis=0, out=sorted_positions)
        row_sequence = _NO_SEQUENCE
        early_rows = 0  # rows before the late ones
        if late_rows is not None:
            late_in_cell_order = late_rows[order]
            if late_in_cell_order.any():
                early = np.flatnonzero(~late_in_cell_order)
                early_rows = len(early)
                row_sequence = np.concatenate([early, np.flatnonzero(late_in_cell_order)])
        arguments = (sorted_positions, state.radii[order], skin, state.owned_count,
                     order, sorted_cells, starts, dimensions, _FORWARD_ROWS, sorted_materials,
                     self.cohesion_reach, self.largest_reach > 0.0, row_sequence, offsets)
        # The partners and the history are the leading rows of buffers kept from build to build: megabyte
        # arrays allocated afresh at every rebuild cost page faults (or heap fragments that stay resident).
        # The old list is dead here (its records were taken).  One pass when the capacity guess (last
        # size + margin) suffices, two otherwise.
        capacity = int(1.25 * self.pair_count) + 4 * count
        if not capacity <= len(self._partner_buffer) <= SLACK * capacity:
            self._partner_buffer = np.empty(capacity, dtype=np.int32)
        needed = _fill_pairs(*arguments, self._partner_buffer)
        if needed > len(self._partner_buffer):
            self._partner_buffer = np.empty(int(1.25 * needed), dtype=np.int32)
            _fill_pairs(*arguments, self._partner_buffer)
        if not needed <= len(self._history_buffer) <= SLACK * needed + 1024:
            self._history_buffer = np.empty((int(1.1 * needed) + 1024, len(self.history_signs)))
        if len(row_sequence):
            order = order[row_sequence]
        body = state.fields.get("clump_body")
        if body is not None:  # members of one rigid clump never interact (pdemfem.clumps.bodies)
            from pdemfem.clumps.bodies import drop_same_body_pairs

            needed = drop_same_body_pairs(order, offsets, self._partner_buffer, body)
        self.row_particles = order
        self.offsets = offsets
        self.partners = self._partner_buffer[:needed]
        self._split_at_ghosts(state.owned_count, early_rows)
        self.history = self._history_buffer[:needed]
        self.history[:] = 0.0
        self._restore(state.ids, state.owned_count, records)
        self._loaded_records = None
        self.builds += 1

    def _split_at_ghosts(self, owned_count: int, early_rows: int = 0) -> None:
        """Order each row's partners so that its pairs of two owned particles come first, and keep the row
        ranges of both kinds: `interior` (row_particles, starts, ends) over every row, `boundary` over the
        rows with pairs with a ghost.  The force pass over the interior needs no ghost's state, so it runs
        while the ghosts' per-step update travels (ParticleSystem.step).

        The first `early_rows` rows (the particles not among build's `late_rows`) hold no pair with a ghost and
        are not read: an owned particle within the list's reach of a ghost is within the ghost cutoff of the box
        that ghost lies in (a clump member sticks out of it by at most the protrusion the cutoff adds), so it is
        among the particles sent there, which are late rows.  On 2 ranks of the 28k settle bed this pass read
        all 15,500 rows (0.17-0.22 ms a rebuild) for the ~3,000 late ones."""
        order, offsets = self.row_particles, self.offsets
        if owned_count == len(order):  # no ghosts: every pair is interior
            self.interior = (order, offsets[:-1], offsets[1:])
            self.boundary = (order[:0], offsets[:0], offsets[:0])
            self.interior_pair_count = self.pair_count
            return
        interior_ends = np.empty(len(order), dtype=np.int64)
        _owned_partners_first(order, offsets, self.partners, owned_count, interior_ends, early_rows)
        rows = np.flatnonzero(interior_ends[early_rows:] < offsets[early_rows + 1:]) + early_rows
        self.interior = (order, offsets[:-1], interior_ends)
        self.boundary = (order[rows], interior_ends[rows], offsets[1:][rows])
        self.interior_pair_count = self.pair_count - int(np.sum(self.boundary[2] - self.boundary[1]))

    def contact_records(self, ids: np.ndarray, owned_count: int, wall_candidates=None,
                        one_per_pair: bool = False) -> np.ndarray:
        """History of the springs in use, one row per owned particle in contact (one per pair with
        `one_per_pair`, when no particle migrates before the records are restored: pdemfem.neighbors.history),
        followed by the plane-wall contacts' records when `wall_candidates` = (particles, walls, history) is
        given (pdemfem.walls.plane.PlaneWalls.candidates); after load_state_dict, the loaded records (walls'
        included) until the next build."""
        if self._loaded_records is not None:
            return self._loaded_records
        # Into a buffer kept from rebuild to rebuild (its leading rows are returned: the caller uses them before
        # the next collection), for the reason the partners' buffer is kept: 1.3 ms against 1.7-2.0 ms (up to
        # 6 ms when the allocator maps the fresh array) for the settle benchmark's 110,000 records.
        collected_into = self._records.rows
        count = self._collect_records(ids, owned_count, wall_candidates, collected_into, one_per_pair)
        records = self._records.at_least(count, collected_into.shape[1])
        if records is not collected_into:  # too small (or far too large): collected again into the new one
            self._collect_records(ids, owned_count, wall_candidates, records, one_per_pair)
        return records[:count]

    def _collect_records(self, ids, owned_count, wall_candidates, records, one_per_pair) -> int:
        count = collect_records_into(self.row_particles, self.offsets, self.partners, self.history, ids, owned_count,
                                     self.history_signs, records, one_per_pair)
        if wall_candidates is not None:
            count = collect_wall_records_into(*wall_candidates, ids, records, count)
        return count

    # ------------------------------------------------------------ checkpoints
    def state_dict(self, ids: np.ndarray, owned_count: int, wall_candidates=None) -> dict:
        """The contact records (the plane walls' too, with `wall_candidates`) as CONTACT_ROWS keyed by the
        (owner id, partner id) pairs: one per owned particle of a pair, as a restart on other ranks needs,
        in an array of their own (not the rebuilds' buffer, sized for one per pair on one rank)."""
        records = self._loaded_records
        if records is None:
            width = RECORD_KEYS + len(self.history_signs)
            records = np.empty((self._collect_records(ids, owned_count, wall_candidates, np.empty((0, width)),
                                                      False), width))
            self._collect_records(ids, owned_count, wall_candidates, records, False)
        return {"pairs": kinds.Entry(kinds.CONTACT_KEYS, np.ascontiguousarray(records[:, :2]).astype(np.int64)),
                "history": kinds.Entry(kinds.CONTACT_ROWS, np.ascontiguousarray(records[:, 2:]))}

    def load_state_dict(self, state: dict, comm=None, ids=None) -> None:
        """Records from a checkpoint (this rank's share of the pair-sorted rows); with `comm` (several
        ranks) they are routed to the rank whose (id-sorted) share of the particles, `ids`, holds
        their owner.  The next build restores them."""
        from pdemfem.parallel.exchange import route_records_to_owner_share

        pairs = np.asarray(state["pairs"])
        history = np.asarray(state["history"], dtype=np.float64)
        # The width is the stored dataset's, the same on every rank: all refuse together.
        if history.ndim == 2 and history.shape[1] != len(self.history_signs):
            raise kinds.StateMismatch(
                f"its contacts store {history.shape[1]} history columns each, this scene's contact laws keep "
                f"{len(self.history_signs)}: a change of the contact laws that alters what a contact stores (friction "
                f"switched on or off, the rolling model, jkr) cannot continue the stored contacts, so it is refused "
                f"even with --force; restore the interactions of the scene that wrote the checkpoint")
        records = np.column_stack([pairs.astype(np.float64), history])  # widths from the arrays
        if comm is not None and comm.size > 1:
            records = route_records_to_owner_share(comm, ids, records)
        self._loaded_records = np.ascontiguousarray(records)

    def _restore(self, ids, owned_count, records):
        records = np.ascontiguousarray(records)
        if len(records) and records.shape[1] != RECORD_KEYS + len(self.history_signs):
            raise ValueError(f"contact records of {records.shape[1] - RECORD_KEYS} history columns for a list of "
                             f"{len(self.history_signs)}")
        restore_records(self.row_particles, self.offsets, self.partners, self.history, ids, owned_count,
                        records, self.history_signs)

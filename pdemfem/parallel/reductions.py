"""The DEM step's reductions over the ranks: one MAX and one SUM per step, buffer-based (on up to
GATHERED_SUM_RANKS ranks both in one Allgather, below).

A small Allreduce costs a network latency (microseconds on one node, tens across nodes) whatever
it carries up to a few kilobytes, and every rank waits in it for the slowest: the number of
collectives per step, not their size, is what costs.  So a step makes at most two:

* MAX (`largest`): the largest particle displacement since the list build, which decides the
  rebuild on every rank alike (and feeds the run monitor's runaway stop);
* SUM (`start_sum`, `finish_sum`): the contact energies and count of the step, the plane walls' forces and
  every contributor's totals (a mesh or cylinder wall's force, moment and work; a solid
  surface's force and moment), packed into one preallocated float64 buffer.

Both use numpy buffers (no pickling).  The SUM adds the values the separate reductions added before,
element by element (in rank order where gathered: on 2 ranks the same two numbers as before).

The SUM may be left pending (`start_sum`) and finished at the next step's MAX (`finish_sum`;
ParticleSystem.defer_step_sum).  Every rank then waits once per step instead of twice: the step's two
halves load the ranks differently (the kicks and drift go with the particle count, the forces with the
contacts), and a decomposition that balances the whole step leaves each rank waiting for the other in one
of the two when each half ends in a collective.

On up to GATHERED_SUM_RANKS ranks the pending SUM travels with the next MAX in one Allgather of each
rank's (displacement, sums) row, and every rank adds the rows in rank order: one collective per step
instead of an Iallreduce posted and waited for beside the MAX (15-20 us a step on 2 ranks, where a step
of the 28,000-particle settle bed takes ~1.5 ms).  A SUM finished before the next MAX (read between steps,
or a scene with FE solids) is gathered and added the same way, so the values do not depend on when it is
finished.  Beyond that many ranks the gathered rows would grow with the rank count, so the SUM is an
Iallreduce there, finished at the MAX.
"""
from __future__ import annotations

import numpy as np
from mpi4py import MPI


# Up to this many ranks a pending SUM is gathered with the next MAX (see the module's doc).
GATHERED_SUM_RANKS = 16


class StepReductions:
    """Preallocated buffers for the two collectives of a DEM step (call on every rank)."""

    def __init__(self, gathered_sum_ranks: int = GATHERED_SUM_RANKS):
        self.gathered_sum_ranks = gathered_sum_ranks
        self._largest = np.zeros(1)
        self._sums = np.zeros(0)
        self._request = None  # the SUM in flight (start_sum, Iallreduce), if any
        self._held = None  # the communicator of a SUM started and held for gathering, if any
        self._summed = False  # the held SUM was gathered and added (with the MAX), not yet unpacked
        self._row = np.zeros(0)  # (displacement, sums) of this rank
        self._rows = np.zeros(0)  # every rank's row
        self._pending = None  # what finish_sum unpacks it into

    def largest(self, comm, value: float) -> float:
        """The largest `value` over the ranks: one Allreduce MAX of one double, or, with a SUM held, one
        Allgather that carries the SUM too."""
        if self._held is not None:
            rows = self._gather(comm, value)
            return float(rows[:, 0].max())
        self._largest[0] = value
        comm.Allreduce(MPI.IN_PLACE, self._largest, op=MPI.MAX)
        return float(self._largest[0])

    def _gather(self, comm, value: float) -> np.ndarray:
        """Gather every rank's (value, sums) row and add the sums in rank order into the buffer."""
        width = self._sums.size + 1
        if self._row.size != width:
            self._row = np.zeros(width)
        if self._rows.size != comm.size * width:
            self._rows = np.zeros(comm.size * width)
        self._row[0] = value
        self._row[1:] = self._sums
        comm.Allgather(self._row, self._rows)
        rows = self._rows.reshape(comm.size, width)
        summed = self._sums
        summed[:] = rows[0, 1:]
        for rank in range(1, comm.size):
            summed += rows[rank, 1:]
        self._held = None
        self._summed = True
        return rows

    @property
    def pending(self) -> bool:
        """A SUM started (start_sum) and not yet finished."""
        return self._request is not None or self._held is not None or self._summed

    def start_sum(self, comm, scalars, plane_forces: np.ndarray, contributors) -> None:
        """Start one SUM over the ranks (held for the next MAX, or a non-blocking Iallreduce) of `scalars`, the
        plane walls' forces and each contributor's `local_totals()`; finish_sum puts them back summed (the forces
        in place, the contributors' through `take_summed_totals`).  Until then they hold this rank's values."""
        assert not self.pending, "finish the step's SUM before starting the next"
        # Written straight into the kept buffer (a list of parts and their sizes cost ~5 us of a ~60 us step on
        # 2 ranks).
        scalar_count = len(scalars)
        plane_end = scalar_count + plane_forces.size
        totals = [np.asarray(contributor.local_totals(), dtype=float).reshape(-1) for contributor in contributors]
        sizes = [part.size for part in totals]
        size = plane_end + sum(sizes)
        if self._sums.size != size:
            self._sums = np.zeros(size)
        buffer = self._sums
        buffer[:scalar_count] = scalars
        buffer[scalar_count:plane_end] = plane_forces.reshape(-1)
        offset = plane_end
        for part in totals:
            buffer[offset:offset + part.size] = part
            offset += part.size
        self._pending = (scalar_count, plane_forces, contributors, sizes)
        if comm.size <= self.gathered_sum_ranks:
            self._held = comm
        else:
            self._request = comm.Iallreduce(MPI.IN_PLACE, buffer, op=MPI.SUM)

    def finish_sum(self) -> list:
        """Finish the started SUM (collective when it has not travelled with a MAX); put the plane walls'
        forces and the contributors' totals in place and return the summed scalars (a list of floats)."""
        if self._held is not None:
            self._gather(self._held, 0.0)
        elif self._request is not None:
            self._request.Wait()
            self._request = None
        self._summed = False
        scalar_count, plane_forces, contributors, sizes = self._pending
        self._pending = None
        buffer = self._sums
        offset = scalar_count + plane_forces.size
        plane_forces.reshape(-1)[:] = buffer[scalar_count:offset]
        for contributor, size in zip(contributors, sizes):
            contributor.take_summed_totals(buffer[offset:offset + size].copy())
            offset += size
        return buffer[:scalar_count].tolist()

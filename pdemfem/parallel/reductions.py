"""The DEM step's reductions over the ranks: one MAX and one SUM per step, each a single
buffer-based Allreduce.

A small Allreduce costs a network latency (microseconds on one node, tens across nodes) whatever
it carries up to a few kilobytes, and every rank waits in it for the slowest: the number of
collectives per step, not their size, is what costs.  So a step makes exactly two:

* MAX (`largest`): the largest particle displacement since the list build, which decides the
  rebuild on every rank alike (and feeds the run monitor's runaway stop);
* SUM (`start_sum`, `finish_sum`): the contact energies and count of the step, the plane walls' forces and
  every contributor's totals (a mesh or cylinder wall's force, moment and work; a solid
  surface's force and moment), packed into one preallocated float64 buffer.

Both use numpy buffers (no pickling).  The SUM adds exactly the values the separate
reductions added before, element by element, so results do not change.

The SUM may be left in flight (`start_sum`, a non-blocking Iallreduce) and finished at the next
step's MAX (`finish_sum`; ParticleSystem.defer_step_sum).  Every rank then waits once per step
instead of twice: the step's two halves load the ranks differently (the kicks and drift go with
the particle count, the forces with the contacts), and a decomposition that balances the whole
step leaves each rank waiting for the other in one of the two when each half ends in a collective.
"""
from __future__ import annotations

import numpy as np
from mpi4py import MPI


class StepReductions:
    """Preallocated buffers for the two collectives of a DEM step (call on every rank)."""

    def __init__(self):
        self._largest = np.zeros(1)
        self._sums = np.zeros(0)
        self._request = None  # the SUM in flight (start_sum), if any
        self._pending = None  # what finish_sum unpacks it into

    def largest(self, comm, value: float) -> float:
        """The largest `value` over the ranks (one Allreduce MAX of one double)."""
        self._largest[0] = value
        comm.Allreduce(MPI.IN_PLACE, self._largest, op=MPI.MAX)
        return float(self._largest[0])

    @property
    def pending(self) -> bool:
        """A SUM started (start_sum) and not yet finished."""
        return self._request is not None

    def start_sum(self, comm, scalars, plane_forces: np.ndarray, contributors) -> None:
        """Start one SUM over the ranks (a non-blocking Iallreduce) of `scalars`, the plane walls' forces and
        each contributor's `local_totals()`; finish_sum puts them back summed (the forces in place, the
        contributors' through `take_summed_totals`).  Until then they hold this rank's values."""
        assert self._request is None, "finish the step's SUM before starting the next"
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
        self._request = comm.Iallreduce(MPI.IN_PLACE, buffer, op=MPI.SUM)

    def finish_sum(self) -> list:
        """Wait for the started SUM; put the plane walls' forces and the contributors' totals in place and
        return the summed scalars (a list of floats)."""
        self._request.Wait()
        self._request = None
        scalar_count, plane_forces, contributors, sizes = self._pending
        self._pending = None
        buffer = self._sums
        offset = scalar_count + plane_forces.size
        plane_forces.reshape(-1)[:] = buffer[scalar_count:offset]
        for contributor, size in zip(contributors, sizes):
            contributor.take_summed_totals(buffer[offset:offset + size].copy())
            offset += size
        return buffer[:scalar_count].tolist()

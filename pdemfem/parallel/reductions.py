"""The DEM step's reductions over the ranks: one MAX and one SUM per step, each a single
buffer-based Allreduce.

A small Allreduce costs a network latency (microseconds on one node, tens across nodes) whatever
it carries up to a few kilobytes, and every rank waits in it for the slowest: the number of
collectives per step, not their size, is what costs.  So a step makes exactly two:

* MAX (`largest`): the largest particle displacement since the list build, which decides the
  rebuild on every rank alike (and feeds the run monitor's runaway stop);
* SUM (`sum_totals`): the contact energies and count of the step, the plane walls' forces and
  every contributor's totals (a mesh or cylinder wall's force, moment and work; a solid
  surface's force and moment), packed into one preallocated float64 buffer.

Both use numpy buffers (no pickling).  The SUM adds exactly the values the separate
reductions added before, element by element, so results do not change.
"""
from __future__ import annotations

import numpy as np
from mpi4py import MPI


class StepReductions:
    """Preallocated buffers for the two collectives of a DEM step (call on every rank)."""

    def __init__(self):
        self._largest = np.zeros(1)
        self._sums = np.zeros(0)

    def largest(self, comm, value: float) -> float:
        """The largest `value` over the ranks (one Allreduce MAX of one double)."""
        self._largest[0] = value
        comm.Allreduce(MPI.IN_PLACE, self._largest, op=MPI.MAX)
        return float(self._largest[0])

    def sum_totals(self, comm, scalars, plane_forces: np.ndarray, contributors) -> np.ndarray:
        """One Allreduce SUM of `scalars`, the plane walls' forces (summed in place) and each
        contributor's `local_totals()` (handed back through `take_summed_totals`).  Returns the
        summed scalars."""
        parts = [np.asarray(scalars, dtype=float), plane_forces.reshape(-1)]
        parts += [np.asarray(contributor.local_totals(), dtype=float) for contributor in contributors]
        size = sum(part.size for part in parts)
        if self._sums.size != size:
            self._sums = np.zeros(size)
        buffer = self._sums
        offset = 0
        for part in parts:
            buffer[offset:offset + part.size] = part
            offset += part.size
        comm.Allreduce(MPI.IN_PLACE, buffer, op=MPI.SUM)
        summed_scalars = buffer[:parts[0].size].copy()
        offset = parts[0].size
        plane_forces.reshape(-1)[:] = buffer[offset:offset + parts[1].size]
        offset += parts[1].size
        for contributor, part in zip(contributors, parts[2:]):
            contributor.take_summed_totals(buffer[offset:offset + part.size].copy())
            offset += part.size
        return summed_scalars

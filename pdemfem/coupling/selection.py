"""Which nodes of a solid's contact surface a rank gathers: the triangles near its own particles.

The DEM side is cut into one box per rank (RCB) and a rank computes the triangle contacts of the
particles it owns only, so it needs the current state of the triangles its particles can reach, not
of the whole surface.  A *selection* (one per coupled surface and rank) is

    region   Q = the box of the rank's owned particles at the last list build, widened by skin/2:
             between two builds no particle moves further than skin/2 (the list's own rebuild
             rule), so every owned particle stays in Q until the next build
    rows     the surface nodes of every triangle whose bounding box (at the selection's positions)
             meets Q widened by reach = largest radius + cohesion reach + margin
    gather   a PETSc scatter of those nodes from their owners (fem/surface.py NodeGather)

with margin = MARGIN_RADII largest particle radii.  The triangles left out keep their vertex data
of the selection's time.  They cannot touch a particle while

    (a) the particle region stays within Q_selection widened by margin/2 (checked at every list
        build: particles migrate, rebalance, arrive only then), and
    (b) no surface node has moved more than margin/2 since the selection (the surface moves only at
        the FE advances),

since a left-out triangle's box, stale or current, then stays further than largest radius +
cohesion reach from every owned particle (margin - margin/2 - margin/2 = 0 to spare beyond the contact
reach).  When (a) fails on any rank, every rank selects anew at once (one MAX reduction at each list
build, before the contacts; creating a scatter is collective).  For (b) each rank measures, after
every advance, the drift of the surface nodes it owns in the FE layout (no communication); a drift
beyond margin/4 rides the next DEM step's one SUM as a flag (no collective of its own) and every rank
selects anew at the following advance.  The quarter margin left covers that one advance's motion: a
surface moving a particle radius (margin/4) within one advance already overlaps a touching grain by a
radius in one step, beyond what the coupled step resolves.
"""
from __future__ import annotations

import numpy as np
from numba import njit

from pdemfem.fem.surface import NodeGather

# The margin, in largest particle radii: wider selects more nodes, narrower selects anew more often.
MARGIN_RADII = 4.0


def particle_region(positions, skin: float):
    """(lower, upper) of the box of `positions` widened by skin/2, None without particles."""
    if not len(positions):
        return None
    return positions.min(axis=0) - 0.5 * skin, positions.max(axis=0) + 0.5 * skin


def region_within(inner, outer, slack: float) -> bool:
    """Whether box `inner` lies in box `outer` widened by slack (an empty inner lies anywhere)."""
    if inner is None:
        return True
    if outer is None:
        return False
    return bool(np.all(inner[0] >= outer[0] - slack) and np.all(inner[1] <= outer[1] + slack))


def rows_near(vertices, triangles, region, reach: float) -> np.ndarray:
    """Rows (into vertices, ascending) of the vertices of every triangle whose bounding box meets `region`
    widened by reach (none for an empty region)."""
    if region is None or not len(triangles):
        return np.zeros(0, dtype=np.int64)
    corners = vertices[triangles]                      # (nt, 3, 3)
    lower, upper = corners.min(axis=1), corners.max(axis=1)
    near = np.all((upper >= region[0] - reach) & (lower <= region[1] + reach), axis=1)
    return np.unique(triangles[near])


class SurfaceSelection:
    """A rank's selection (module docstring): its region, rows, gather, and the owned surface nodes'
    displacements when it was made (for the drift test (b))."""

    def __init__(self, gather: NodeGather, region, owned_displacements: np.ndarray):
        self.gather = gather
        self.rows = gather.rows
        self.region = region
        self.owned_displacements = owned_displacements

    def drift(self, local_displacements: np.ndarray, owned_local_rows: np.ndarray) -> float:
        """Largest movement [m] of this rank's owned surface nodes since the selection (local_displacements: the
        rank's (owned nodes, 3) part of the displacement; owned_local_rows: its surface nodes' rows in it)."""
        return largest_drift(local_displacements, owned_local_rows, self.owned_displacements)


@njit(cache=True)
def largest_drift(local_displacements, owned_local_rows, displacements_then):
    """max_k |u[owned_local_rows[k]] - displacements_then[k]| (0 without rows)."""
    largest = 0.0
    for k in range(owned_local_rows.shape[0]):
        row = owned_local_rows[k]
        squared = 0.0
        for axis in range(3):
            step = local_displacements[row, axis] - displacements_then[k, axis]
            squared += step * step
        largest = max(largest, squared)
    return np.sqrt(largest)


@njit(cache=True)
def refresh_rows(rows, reference_positions, displacements, velocities, interval, vertices, vertex_velocities):
    """The selected vertices after an advance: x = X + u, and as velocity the chord (x - x_before) / interval
    (x_before: the vertex as it stands, the state before the advance) or, for interval <= 0, the solid's own."""
    for k in range(rows.shape[0]):
        row = rows[k]
        for axis in range(3):
            position = reference_positions[row, axis] + displacements[k, axis]
            if interval > 0.0:
                vertex_velocities[row, axis] = (position - vertices[row, axis]) / interval
            else:
                vertex_velocities[row, axis] = velocities[k, axis]
            vertices[row, axis] = position

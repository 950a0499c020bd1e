"""Cell binning: a uniform grid over the particles' bounding box."""
from __future__ import annotations

import numpy as np
from numba import njit

from pdemfem.errors import SolverError

# A grid with far more cells than particles (a sparse, spread-out scene) costs
# memory and stencil time for nothing: grow the cells instead.
MAXIMUM_CELLS_PER_PARTICLE = 8
# Particles spread over more cell sizes than this have left the coordinate range where float64 resolves their
# contact overlaps (the scene's validation allows |x| <= 1e9 smallest radii): a diverged run, not a scene.
LARGEST_EXTENT_IN_CELLS = 1.0e10


@njit(cache=True)
def bounding_box(positions):
    """(lower, upper) corners of the points (one pass; numpy's axis-0 min/max is strided and slow)."""
    lower = np.full(3, np.inf)
    upper = np.full(3, -np.inf)
    for i in range(positions.shape[0]):
        for axis in range(3):
            value = positions[i, axis]
            if value < lower[axis]:
                lower[axis] = value
            if value > upper[axis]:
                upper[axis] = value
    return lower, upper


def cell_grid(positions: np.ndarray, cell_size: float):
    """(lower corner, cell size, cells per axis) covering all positions."""
    count = len(positions)
    if not count:
        return np.zeros(3), float(cell_size), np.ones(3, dtype=np.int64)
    lower, upper = bounding_box(positions)
    if not np.all(upper - lower <= LARGEST_EXTENT_IN_CELLS * cell_size):
        raise SolverError("particle positions",
                          f"the simulation diverged: the particles spread from {_point(lower)} to {_point(upper)} m, "
                          f"over more than {LARGEST_EXTENT_IN_CELLS:.0e} neighbour cells of {cell_size:.3g} m (a "
                          f"particle was shot away)",
                          "run the scene with `pdemfem run` or Simulation.run(), whose run monitor stops a diverging "
                          "run with its likely cause, and check the step with `pdemfem check` (dt: auto)")
    lower = lower - 1e-9 * max(cell_size, 1.0)
    size = float(cell_size)
    while True:
        dimensions = np.maximum(np.floor((upper - lower) / size).astype(np.int64) + 1, 1)
        # Counted in floats: the product of three large axis counts overflows int64.
        if float(np.prod(dimensions.astype(np.float64))) <= max(MAXIMUM_CELLS_PER_PARTICLE * count, 64):
            return lower, size, dimensions
        size *= 1.5


def _point(values) -> str:
    return "[" + ", ".join(f"{float(value):.3g}" for value in values) + "]"


@njit(cache=True)
def cell_indices(positions, lower, cell_size, dimensions):
    """Linear cell index of each position (x fastest), clamped into the grid."""
    cells = np.empty(positions.shape[0], dtype=np.int64)
    for i in range(positions.shape[0]):
        index = 0
        stride = 1
        for axis in range(3):
            coordinate = int(np.floor((positions[i, axis] - lower[axis]) / cell_size))
            coordinate = min(max(coordinate, 0), dimensions[axis] - 1)
            index += stride * coordinate
            stride *= dimensions[axis]
        cells[i] = index
    return cells


@njit(cache=True)
def cell_starts(sorted_cells, cell_count):
    """Offsets such that particles of cell c are [starts[c], starts[c+1]) in sorted order (counts per
    cell, summed: a binary search per cell, numpy's searchsorted over arange(cells), costs several times more)."""
    return cell_starts_of_unsorted(sorted_cells, cell_count)


@njit(cache=True)
def sort_by_cell(cells, cell_count):
    """(order, starts): the particles in cell order, ties in row order (a counting sort: the same
    order as a stable argsort, in two passes), and cell_starts of that order."""
    starts = cell_starts_of_unsorted(cells, cell_count)
    next_slot = starts[:-1].copy()
    order = np.empty(cells.shape[0], dtype=np.int64)
    for p in range(cells.shape[0]):
        cell = cells[p]
        order[next_slot[cell]] = p
        next_slot[cell] += 1
    return order, starts


@njit(cache=True)
def cell_starts_of_unsorted(cells, cell_count):
    """cell_starts of the particles once sorted by cell (counts per cell, summed)."""
    starts = np.zeros(cell_count + 1, dtype=np.int64)
    for p in range(cells.shape[0]):
        starts[cells[p] + 1] += 1
    for cell in range(cell_count):
        starts[cell + 1] += starts[cell]
    return starts


@njit(cache=True)
def out_of_order_runs(order):
    """How many rows of `order` do not follow the row before them (order[p] != order[p-1] + 1): the breaks in
    memory locality a permutation would repair.  A particle that moved to a neighbouring cell makes two
    or three breaks, where counting the rows whose index changes would count every row after it."""
    breaks = 0
    for p in range(1, order.shape[0]):
        if order[p] != order[p - 1] + 1:
            breaks += 1
    return breaks

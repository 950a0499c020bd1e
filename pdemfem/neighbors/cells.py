"""Cell binning: a uniform grid over the particles' bounding box."""
from __future__ import annotations

import numpy as np

# A grid with far more cells than particles (a sparse, spread-out scene) costs
# memory and stencil time for nothing: grow the cells instead.
MAXIMUM_CELLS_PER_PARTICLE = 8


def cell_grid(positions: np.ndarray, cell_size: float):
    """(lower corner, cell size, cells per axis) covering all positions."""
    count = len(positions)
    lower = positions.min(axis=0) - 1e-9 * max(cell_size, 1.0)
    upper = positions.max(axis=0)
    size = float(cell_size)
    while True:
        dimensions = np.maximum(np.floor((upper - lower) / size).astype(np.int64) + 1, 1)
        if int(np.prod(dimensions)) <= max(MAXIMUM_CELLS_PER_PARTICLE * count, 64):
            return lower, size, dimensions
        size *= 1.5


def cell_indices(positions: np.ndarray, lower: np.ndarray, cell_size: float, dimensions: np.ndarray) -> np.ndarray:
    """Linear cell index of each position (x fastest)."""
    coordinates = np.floor((positions - lower) / cell_size).astype(np.int64)
    coordinates = np.clip(coordinates, 0, dimensions - 1)
    return coordinates[:, 0] + dimensions[0] * (coordinates[:, 1] + dimensions[1] * coordinates[:, 2])


def cell_starts(sorted_cells: np.ndarray, cell_count: int) -> np.ndarray:
    """Offsets such that particles of cell c are [starts[c], starts[c+1]) in sorted order."""
    return np.searchsorted(sorted_cells, np.arange(cell_count + 1)).astype(np.int64)

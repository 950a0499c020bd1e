"""The linked-cell grid of random sequential insertion: spheres placed so far, and the overlap test of a
candidate against them (single spheres in pdemfem.particles.insert, clump members in pdemfem.clumps.insert).

The grid is flat arrays the caller owns: all_positions (n, 3), all_radii (n,), cell_head (cells,) and
next_in_cell (n,) (-1: end of a cell's chain), with the cells of size cell_size from grid_lower, dimensions
(nx, ny, nz) of them; a point outside is clamped into the nearest cell.
"""
from __future__ import annotations

import numpy as np
from numba import njit


@njit(cache=True)
def cell_of(point, grid_lower, cell_size, dimensions):
    """The linked-cell grid cell (3 indices, clamped to the grid) holding `point`."""
    c = np.empty(3, dtype=np.int64)
    for axis in range(3):
        c[axis] = min(max(int((point[axis] - grid_lower[axis]) / cell_size), 0), dimensions[axis] - 1)
    return c


@njit(cache=True)
def store_sphere(position, radius, stored, all_positions, all_radii, cell_head, next_in_cell, grid_lower,
                 cell_size, dimensions):
    """Put a placed sphere into row `stored` of the linked-cell grid; returns the next free row."""
    all_positions[stored] = position
    all_radii[stored] = radius
    c = cell_of(position, grid_lower, cell_size, dimensions)
    cell = c[0] + dimensions[0] * (c[1] + dimensions[1] * c[2])
    next_in_cell[stored] = cell_head[cell]
    cell_head[cell] = stored
    return stored + 1


@njit(cache=True)
def overlaps_stored(candidate, radius, all_positions, all_radii, cell_head, next_in_cell, grid_lower, cell_size,
                    dimensions):
    """Does a sphere at `candidate` overlap one already stored in the grid (the 27 cells around it)?"""
    nx, ny, nz = dimensions[0], dimensions[1], dimensions[2]
    c = cell_of(candidate, grid_lower, cell_size, dimensions)
    for dz in range(-1, 2):
        for dy in range(-1, 2):
            for dx in range(-1, 2):
                x, y, z = c[0] + dx, c[1] + dy, c[2] + dz
                if x < 0 or y < 0 or z < 0 or x >= nx or y >= ny or z >= nz:
                    continue
                other = cell_head[x + nx * (y + ny * z)]
                while other >= 0:
                    distance = 0.0
                    for axis in range(3):
                        offset = candidate[axis] - all_positions[other, axis]
                        distance += offset * offset
                    limit = radius + all_radii[other]
                    if distance < limit * limit:
                        return True
                    other = next_in_cell[other]
    return False

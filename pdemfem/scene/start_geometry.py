"""Kernels of the starting-position checks (pdemfem.scene.inputs.validate_start_positions)."""
from __future__ import annotations

import numpy as np
from numba import njit

from pdemfem.walls.triangle_contact import point_triangle_distance_squared


@njit(cache=True)
def nearest_triangle_distance(positions, vertices, triangles, offsets, items, distance):
    """distance[i] = min(distance[i], distance from positions[i] to the triangles items[offsets[i]:offsets[i+1]])."""
    for i in range(positions.shape[0]):
        best = distance[i] * distance[i]
        for k in range(offsets[i], offsets[i + 1]):
            d2 = point_triangle_distance_squared(positions[i, 0], positions[i, 1], positions[i, 2], vertices,
                                                 triangles, items[k])
            if d2 < best:
                best = d2
        distance[i] = np.sqrt(best)
    return distance


def grid_cells_of(positions, per_cell: float = 2.0):
    """A uniform grid over the points with about `per_cell` points per cell: (origin, cell size, dims,
    order of the points by cell, CSR starts of each cell in `order`)."""
    low = positions.min(axis=0)
    extent = np.maximum(positions.max(axis=0) - low, 0.0)
    # At most ~len/per_cell cells in all (fewer, fuller cells when the points lie in a plane or a line).
    divisions = max(1, int(round((len(positions) / per_cell) ** (1.0 / 3.0))))
    size = float(extent.max()) / divisions
    if not size > 0.0:
        size = 1.0  # all points in one spot: one cell
    dims = np.minimum(np.floor(extent / size).astype(np.int64) + 1, divisions)
    index = np.minimum(((positions - low) / size).astype(np.int64), dims - 1)
    flat = (index[:, 0] * dims[1] + index[:, 1]) * dims[2] + index[:, 2]
    order = np.argsort(flat, kind="stable").astype(np.int64)
    starts = np.searchsorted(flat[order], np.arange(int(np.prod(dims)) + 1)).astype(np.int64)
    return low.astype(np.float64), size, dims, order, starts


@njit(cache=True)
def points_in_tetrahedra(positions, points, cells, origin, size, dims, order, starts, found):
    """found[i] = True when positions[i] lies in (or on) one of the tetrahedra."""
    for c in range(cells.shape[0]):
        a = points[cells[c, 0]]
        b = points[cells[c, 1]]
        d = points[cells[c, 2]]
        e = points[cells[c, 3]]
        lo = np.minimum(np.minimum(a, b), np.minimum(d, e))
        hi = np.maximum(np.maximum(a, b), np.maximum(d, e))
        # Barycentric coordinates: solve [b-a, d-a, e-a] lambda = p - a.
        m00 = b[0] - a[0]
        m01 = d[0] - a[0]
        m02 = e[0] - a[0]
        m10 = b[1] - a[1]
        m11 = d[1] - a[1]
        m12 = e[1] - a[1]
        m20 = b[2] - a[2]
        m21 = d[2] - a[2]
        m22 = e[2] - a[2]
        det = m00 * (m11 * m22 - m12 * m21) - m01 * (m10 * m22 - m12 * m20) + m02 * (m10 * m21 - m11 * m20)
        if det == 0.0:
            continue
        inv = 1.0 / det
        i00 = (m11 * m22 - m12 * m21) * inv
        i01 = (m02 * m21 - m01 * m22) * inv
        i02 = (m01 * m12 - m02 * m11) * inv
        i10 = (m12 * m20 - m10 * m22) * inv
        i11 = (m00 * m22 - m02 * m20) * inv
        i12 = (m02 * m10 - m00 * m12) * inv
        i20 = (m10 * m21 - m11 * m20) * inv
        i21 = (m01 * m20 - m00 * m21) * inv
        i22 = (m00 * m11 - m01 * m10) * inv
        g0 = np.empty(3, dtype=np.int64)
        g1 = np.empty(3, dtype=np.int64)
        skip = False
        for k in range(3):
            # In floating point first: a tiny cell size would overflow the integer conversion.
            low = np.floor((lo[k] - origin[k]) / size)
            high = np.floor((hi[k] - origin[k]) / size)
            if high < 0.0 or low > dims[k] - 1.0:
                skip = True
                break
            g0[k] = int(max(low, 0.0))
            g1[k] = int(min(high, dims[k] - 1.0))
        if skip:
            continue
        eps = -1e-12
        for gx in range(g0[0], g1[0] + 1):
            for gy in range(g0[1], g1[1] + 1):
                for gz in range(g0[2], g1[2] + 1):
                    flat = (gx * dims[1] + gy) * dims[2] + gz
                    for k in range(starts[flat], starts[flat + 1]):
                        i = order[k]
                        if found[i]:
                            continue
                        px = positions[i, 0] - a[0]
                        py = positions[i, 1] - a[1]
                        pz = positions[i, 2] - a[2]
                        l1 = i00 * px + i01 * py + i02 * pz
                        l2 = i10 * px + i11 * py + i12 * pz
                        l3 = i20 * px + i21 * py + i22 * pz
                        if l1 >= eps and l2 >= eps and l3 >= eps and 1.0 - l1 - l2 - l3 >= eps:
                            found[i] = True
    return found

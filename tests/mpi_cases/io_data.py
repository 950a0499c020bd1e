"""Deterministic data shared by the I/O MPI cases (tests/mpi_cases/io_*.py) and tests/test_io_*.py.

Every value is a function of the global particle id / node coordinates and the step,
so a test can recompute what any rank count must have written.
"""
from __future__ import annotations

import numpy as np

PARTICLE_STEPS = [(0, 0.0, 50), (10, 1.0e-3, 173), (20, 2.0e-3, 260)]  # (step, time, global count)


def owned_range(count: int, rank: int, size: int) -> tuple[int, int]:
    """An uneven split (rank r gets a share proportional to r + 1) so offsets are exercised."""
    weights = np.arange(1, size + 1, dtype=np.float64)
    bounds = np.concatenate([[0], np.floor(np.cumsum(weights) / weights.sum() * count)]).astype(int)
    return int(bounds[rank]), int(bounds[rank + 1])


def particle_arrays(ids: np.ndarray, step: int) -> dict:
    ids = np.asarray(ids, dtype=np.int64)
    s = float(step)
    base = ids.astype(np.float64)
    column = np.arange(3, dtype=np.float64)
    return {
        "ids": ids.copy(),
        "positions": np.sin(base[:, None] * 0.37 + column + s * 0.01),
        "velocities": np.cos(base[:, None] * 0.11 - column * 2.0 + s),
        "radii": 1.0e-3 * (1.0 + (ids % 7)),
        "forces": base[:, None] * (column + 1.0) * 1.0e-6 + s,
        "temperature": 293.15 + base * 0.5 + s,
    }


def rank_particle_ids(count: int, rank: int, size: int, step: int) -> np.ndarray:
    """This rank's owned ids, deliberately unsorted (a spatial decomposition does not sort by id)."""
    first, stop = owned_range(count, rank, size)
    ids = np.arange(first, stop, dtype=np.int64)
    rng = np.random.default_rng(1000 * step + rank)
    return rng.permutation(ids)


# ------------------------------------------------------------------- tet mesh
def box_tet_mesh(nx: int = 4, ny: int = 3, nz: int = 2):
    """Unit box, each hexahedron split into 6 tetrahedra (Kuhn); nodes numbered x-fastest."""
    xs, ys, zs = (np.linspace(0.0, 1.0, n + 1) for n in (nx, ny, nz))
    Z, Y, X = np.meshgrid(zs, ys, xs, indexing="ij")
    points = np.column_stack([X.ravel(), Y.ravel(), Z.ravel()])

    def node(i, j, k):
        return (k * (ny + 1) + j) * (nx + 1) + i

    kuhn = [(0, 1, 3, 7), (0, 1, 5, 7), (0, 2, 3, 7), (0, 2, 6, 7), (0, 4, 5, 7), (0, 4, 6, 7)]
    cells = []
    for k in range(nz):
        for j in range(ny):
            for i in range(nx):
                corners = [node(i + (c & 1), j + ((c >> 1) & 1), k + ((c >> 2) & 1)) for c in range(8)]
                cells.extend([[corners[a] for a in tet] for tet in kuhn])
    return points, np.array(cells, dtype=np.int64)


def split_mesh(points, cells, rank: int, size: int):
    """Owned node range (even split) and owned cells (a cell belongs to the owner of its first node)."""
    n = len(points)
    first, stop = n * rank // size, n * (rank + 1) // size
    owner = np.searchsorted([n * r // size for r in range(1, size)], cells[:, 0], side="right")
    return points[first:stop], cells[owner == rank], first


def nodal_fields(points: np.ndarray, step: int) -> dict:
    s = float(step)
    return {
        "displacements": 1.0e-3 * np.sin(points * (1.0 + s)),
        "velocities": np.cos(points * 2.0 - s),
        "temperature": 300.0 + points[:, 0] * 10.0 + s,
    }


def cell_fields(points: np.ndarray, cells: np.ndarray, step: int) -> dict:
    centroid = points[cells].mean(axis=1)
    return {"von_mises": 1.0e6 * (centroid[:, 0] + 2.0 * centroid[:, 1] + 3.0 * centroid[:, 2]) + step}

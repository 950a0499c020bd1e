"""Reference tetrahedra (P1: 4 nodes, P2: 10 nodes) and exact quadrature rules.

Node order follows VTK/meshio: corners 0-3, then the midside nodes of edges
(0,1), (1,2), (2,0), (0,3), (1,3), (2,3).  Elements are straight-sided, so the
Jacobian is constant per cell and only the reference gradients are tabulated.
"""
from __future__ import annotations

from dataclasses import dataclass
from math import ceil

import numpy as np

# Edges of a tetrahedron in VTK tetra10 order (local corner pairs).
TET_EDGES = np.array([[0, 1], [1, 2], [2, 0], [0, 3], [1, 3], [2, 3]], dtype=np.int64)
# Faces opposite to corners 3, 2, 1, 0 (any order; orientation is fixed per use).
TET_FACES = np.array([[0, 1, 2], [0, 1, 3], [0, 2, 3], [1, 2, 3]], dtype=np.int64)


def barycentric(points: np.ndarray) -> np.ndarray:
    """(n,4) barycentric coordinates L0..L3 of reference points (n,3)."""
    points = np.asarray(points, dtype=float)
    return np.column_stack([1.0 - points.sum(axis=1), points])


# d L_i / d xi_j
_BARYCENTRIC_GRADIENTS = np.array([[-1.0, -1.0, -1.0], [1.0, 0.0, 0.0], [0.0, 1.0, 0.0], [0.0, 0.0, 1.0]])


def shape_values(degree: int, points: np.ndarray) -> np.ndarray:
    """Shape functions (nq, nen) at reference points."""
    L = barycentric(points)
    if degree == 1:
        return L
    corners = L * (2.0 * L - 1.0)
    edges = 4.0 * L[:, TET_EDGES[:, 0]] * L[:, TET_EDGES[:, 1]]
    return np.hstack([corners, edges])


def shape_gradients(degree: int, points: np.ndarray) -> np.ndarray:
    """Reference gradients (nq, nen, 3) at reference points."""
    L = barycentric(points)
    G = _BARYCENTRIC_GRADIENTS
    nq = L.shape[0]
    if degree == 1:
        return np.broadcast_to(G, (nq, 4, 3)).copy()
    grads = np.empty((nq, 10, 3))
    for i in range(4):
        grads[:, i, :] = (4.0 * L[:, i] - 1.0)[:, None] * G[i]
    for e, (i, j) in enumerate(TET_EDGES):
        grads[:, 4 + e, :] = 4.0 * (L[:, j][:, None] * G[i] + L[:, i][:, None] * G[j])
    return grads


def collapsed_gauss_rule(degree: int) -> tuple[np.ndarray, np.ndarray]:
    """Conical-product Gauss rule on the reference tetrahedron, exact for polynomials of `degree`.

    The cube [0,1]^3 maps to the tetrahedron by xi = a, eta = b(1-a), zeta = c(1-a)(1-b)
    with Jacobian (1-a)^2 (1-b), which raises the degree in a by 2 and in b by 1:
    n Gauss points per direction with 2n-1 >= degree+2 make the rule exact.
    """
    n = max(1, ceil((degree + 3) / 2))
    x, w = np.polynomial.legendre.leggauss(n)
    x = 0.5 * (x + 1.0)
    w = 0.5 * w
    a, b, c = np.meshgrid(x, x, x, indexing="ij")
    wa, wb, wc = np.meshgrid(w, w, w, indexing="ij")
    points = np.column_stack([a.ravel(), (b * (1 - a)).ravel(), (c * (1 - a) * (1 - b)).ravel()])
    weights = (wa * wb * wc * (1 - a) ** 2 * (1 - b)).ravel()
    return points, weights


def symmetric_rule(degree: int) -> tuple[np.ndarray, np.ndarray]:
    """Cheapest symmetric rules: 1 point (degree 1), 4 points (degree 2); else collapsed Gauss."""
    if degree <= 1:
        return np.array([[0.25, 0.25, 0.25]]), np.array([1.0 / 6.0])
    if degree == 2:
        a, b = 0.5854101966249685, 0.1381966011250105
        points = np.array([[b, b, b], [a, b, b], [b, a, b], [b, b, a]])
        return points, np.full(4, 1.0 / 24.0)
    return collapsed_gauss_rule(degree)


@dataclass(frozen=True)
class ReferenceElement:
    """Tabulated shape data of one element type, ready for the kernels (flat float64 arrays)."""

    degree: int
    nodes_per_cell: int
    stiffness_gradients: np.ndarray  # (nq, nen, 3) reference gradients at the stiffness points
    stiffness_weights: np.ndarray  # (nq,)
    mass_values: np.ndarray  # (nq, nen) shape values at the mass/load points
    mass_gradients: np.ndarray  # (nq, nen, 3)
    mass_weights: np.ndarray  # (nq,)
    centroid_gradients: np.ndarray  # (nen, 3) reference gradients at the centroid (stress output)
    centroid_values: np.ndarray  # (nen,)


def reference_element(name: str) -> ReferenceElement:
    """P1 or P2: stiffness integrand has degree 2(p-1), mass and thermal loads degree 2p; both exact."""
    degree = {"P1": 1, "P2": 2}[name]
    stiffness_points, stiffness_weights = symmetric_rule(2 * (degree - 1))
    mass_points, mass_weights = symmetric_rule(2 * degree)
    centroid = np.array([[0.25, 0.25, 0.25]])
    return ReferenceElement(
        degree=degree,
        nodes_per_cell=4 if degree == 1 else 10,
        stiffness_gradients=np.ascontiguousarray(shape_gradients(degree, stiffness_points)),
        stiffness_weights=np.ascontiguousarray(stiffness_weights),
        mass_values=np.ascontiguousarray(shape_values(degree, mass_points)),
        mass_gradients=np.ascontiguousarray(shape_gradients(degree, mass_points)),
        mass_weights=np.ascontiguousarray(mass_weights),
        centroid_gradients=np.ascontiguousarray(shape_gradients(degree, centroid)[0]),
        centroid_values=np.ascontiguousarray(shape_values(degree, centroid)[0]),
    )


def p2_connectivity(points: np.ndarray, tets: np.ndarray) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Add straight midside nodes: (points with midsides appended, tets10, edges (ne,2) sorted corner pairs).

    Midside node of edge e is number len(points) + e.
    """
    local_edges = tets[:, TET_EDGES]  # (nc, 6, 2)
    edges = np.sort(local_edges.reshape(-1, 2), axis=1)
    unique_edges, edge_of = np.unique(edges, axis=0, return_inverse=True)
    n_points = points.shape[0]
    midsides = 0.5 * (points[unique_edges[:, 0]] + points[unique_edges[:, 1]])
    tets10 = np.hstack([tets, n_points + edge_of.reshape(-1, 6)])
    return np.vstack([points, midsides]), tets10.astype(np.int64), unique_edges


def edge_midside_nodes(edges: np.ndarray, n_corner_points: int, pairs: np.ndarray) -> np.ndarray:
    """Midside node numbers of corner pairs (m,2) given the sorted edge list of p2_connectivity."""
    keys = edges[:, 0] * n_corner_points + edges[:, 1]
    pairs = np.sort(pairs, axis=1)
    wanted = pairs[:, 0] * n_corner_points + pairs[:, 1]
    where = np.searchsorted(keys, wanted)
    if np.any(where >= len(keys)) or np.any(keys[np.minimum(where, len(keys) - 1)] != wanted):
        raise ValueError("face edge is not an edge of any cell")
    return n_corner_points + where


def split_p2_faces(faces6: np.ndarray) -> np.ndarray:
    """Split 6-node faces (a, b, c, ab, bc, ca) into 4 flat triangles with the parent's orientation."""
    a, b, c, ab, bc, ca = (faces6[:, i] for i in range(6))
    return np.stack(
        [np.column_stack([a, ab, ca]), np.column_stack([ab, b, bc]), np.column_stack([ca, bc, c]), np.column_stack([ab, bc, ca])],
        axis=1,
    ).reshape(-1, 3)

"""Counter-forces of sphere-triangle contacts onto FE nodes.

A contact on a surface triangle carries the force the particle exerts on the
surface and the barycentric weights of the contact point.  For P1 faces the
weights go straight to the triangle's three nodes.  A P2 face (a, b, c, ab, bc,
ca) is mirrored as four flat sub-triangles; the contact point's area
coordinates in the parent face follow from the sub-triangle's weights, and the
force is spread with the quadratic face shape functions.  Either way the
weights sum to one (total force preserved) and reproduce the contact point
(sum w_k x_k = x_c for straight-sided faces), so the total moment is preserved
as well.
"""
from __future__ import annotations

import numpy as np
from numba import njit

# Area coordinates (in the parent face) of the vertices of the four sub-triangles
# [a, ab, ca], [ab, b, bc], [ca, bc, c], [ab, bc, ca] made by fem.elements.split_p2_faces.
_A, _B, _C = (1.0, 0.0, 0.0), (0.0, 1.0, 0.0), (0.0, 0.0, 1.0)
_AB, _BC, _CA = (0.5, 0.5, 0.0), (0.0, 0.5, 0.5), (0.5, 0.0, 0.5)
SUB_TRIANGLE_AREA_COORDINATES = np.array([
    [_A, _AB, _CA],
    [_AB, _B, _BC],
    [_CA, _BC, _C],
    [_AB, _BC, _CA],
])


@njit(cache=True)
def spread_linear(triangles, contact_triangles, contact_weights, contact_forces, node_forces):
    """node_forces[node] += w_k F for the three nodes of each contact's triangle."""
    for c in range(contact_triangles.shape[0]):
        t = contact_triangles[c]
        for k in range(3):
            node = triangles[t, k]
            for axis in range(3):
                node_forces[node, axis] += contact_weights[c, k] * contact_forces[c, axis]


@njit(cache=True)
def spread_quadratic(faces, area_coordinates_of_sub, contact_triangles, contact_weights, contact_forces,
                     node_forces):
    """node_forces[node] += N_k(L) F over the six nodes of each contact's parent P2 face."""
    shape = np.empty(6)
    for c in range(contact_triangles.shape[0]):
        t = contact_triangles[c]
        face = t // 4
        sub = t % 4
        l1 = 0.0
        l2 = 0.0
        l3 = 0.0
        for k in range(3):
            w = contact_weights[c, k]
            l1 += w * area_coordinates_of_sub[sub, k, 0]
            l2 += w * area_coordinates_of_sub[sub, k, 1]
            l3 += w * area_coordinates_of_sub[sub, k, 2]
        shape[0] = l1 * (2.0 * l1 - 1.0)
        shape[1] = l2 * (2.0 * l2 - 1.0)
        shape[2] = l3 * (2.0 * l3 - 1.0)
        shape[3] = 4.0 * l1 * l2
        shape[4] = 4.0 * l2 * l3
        shape[5] = 4.0 * l3 * l1
        for k in range(6):
            node = faces[face, k]
            for axis in range(3):
                node_forces[node, axis] += shape[k] * contact_forces[c, axis]


def parent_faces_from_split(triangles: np.ndarray) -> np.ndarray:
    """(nf, 6) nodes (a, b, c, ab, bc, ca) of P2 faces from their four sub-triangles (rows 4f..4f+3)."""
    sub = triangles.reshape(-1, 4, 3)
    a, ab, ca = sub[:, 0, 0], sub[:, 0, 1], sub[:, 0, 2]
    b, bc = sub[:, 1, 1], sub[:, 1, 2]
    c = sub[:, 2, 2]
    return np.ascontiguousarray(np.column_stack([a, b, c, ab, bc, ca]))

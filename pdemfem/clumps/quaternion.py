"""Unit quaternions q = (w, x, y, z) for rotations: q rotates a body-frame vector into the world frame.

Convention: R(q) v = q v q*, composition q_a (x) q_b applies q_b first.  The kernels work on
single quaternions stored as rows of flat (n, 4) arrays.
"""
from __future__ import annotations

import math

import numpy as np
from numba import njit


@njit(inline="always", cache=True)
def rotation_entries(w, x, y, z):
    """R(q) of a unit quaternion as nine scalars, row by row (r00, r01, r02, r10, ..., r22)."""
    return (1.0 - 2.0 * (y * y + z * z), 2.0 * (x * y - w * z), 2.0 * (x * z + w * y),
            2.0 * (x * y + w * z), 1.0 - 2.0 * (x * x + z * z), 2.0 * (y * z - w * x),
            2.0 * (x * z - w * y), 2.0 * (y * z + w * x), 1.0 - 2.0 * (x * x + y * y))


@njit(cache=True)
def rotation_matrix(w, x, y, z, out):
    """Fill out (3, 3) with R(q) of a unit quaternion."""
    (out[0, 0], out[0, 1], out[0, 2], out[1, 0], out[1, 1], out[1, 2], out[2, 0], out[2, 1],
     out[2, 2]) = rotation_entries(w, x, y, z)


def rotation_matrices(orientations):
    """(n, 3, 3) rotation matrices body -> world of (n, 4) unit quaternions (Python helper)."""
    orientations = np.asarray(orientations, dtype=np.float64).reshape(-1, 4)
    out = np.empty((len(orientations), 3, 3))
    for i, (w, x, y, z) in enumerate(orientations):
        rotation_matrix(w, x, y, z, out[i])
    return out


def quaternion_from_matrix(matrix):
    """Unit quaternion (w >= 0) of a proper rotation matrix (Shepperd's method: the largest pivot avoids
    dividing by a small number)."""
    m = np.asarray(matrix, dtype=np.float64)
    trace = m[0, 0] + m[1, 1] + m[2, 2]
    pivots = [trace, m[0, 0], m[1, 1], m[2, 2]]
    k = int(np.argmax(pivots))
    if k == 0:
        s = 2.0 * math.sqrt(1.0 + trace)
        q = [0.25 * s, (m[2, 1] - m[1, 2]) / s, (m[0, 2] - m[2, 0]) / s, (m[1, 0] - m[0, 1]) / s]
    elif k == 1:
        s = 2.0 * math.sqrt(1.0 + m[0, 0] - m[1, 1] - m[2, 2])
        q = [(m[2, 1] - m[1, 2]) / s, 0.25 * s, (m[0, 1] + m[1, 0]) / s, (m[0, 2] + m[2, 0]) / s]
    elif k == 2:
        s = 2.0 * math.sqrt(1.0 + m[1, 1] - m[0, 0] - m[2, 2])
        q = [(m[0, 2] - m[2, 0]) / s, (m[0, 1] + m[1, 0]) / s, 0.25 * s, (m[1, 2] + m[2, 1]) / s]
    else:
        s = 2.0 * math.sqrt(1.0 + m[2, 2] - m[0, 0] - m[1, 1])
        q = [(m[1, 0] - m[0, 1]) / s, (m[0, 2] + m[2, 0]) / s, (m[1, 2] + m[2, 1]) / s, 0.25 * s]
    q = np.array(q)
    if q[0] < 0.0:
        q = -q
    return q / np.linalg.norm(q)


def quaternion_from_axis_angle(axis, angle):
    """Unit quaternion of a rotation by `angle` (radians) about `axis`."""
    axis = np.asarray(axis, dtype=np.float64)
    axis = axis / np.linalg.norm(axis)
    return np.concatenate([[math.cos(0.5 * angle)], math.sin(0.5 * angle) * axis])


def quaternion_products(a, b):
    """Row-wise products a (x) b of (n, 4) (or (4,)) unit quaternions: the rotation b, then a."""
    a = np.asarray(a, dtype=np.float64).reshape(-1, 4)
    b = np.asarray(b, dtype=np.float64).reshape(-1, 4)
    w1, x1, y1, z1 = a.T
    w2, x2, y2, z2 = b.T
    return np.stack([w1 * w2 - x1 * x2 - y1 * y2 - z1 * z2,
                     w1 * x2 + x1 * w2 + y1 * z2 - z1 * y2,
                     w1 * y2 - x1 * z2 + y1 * w2 + z1 * x2,
                     w1 * z2 + x1 * y2 - y1 * x2 + z1 * w2], axis=1)


def quaternion_conjugates(q):
    """The inverse rotations of (n, 4) unit quaternions."""
    q = np.asarray(q, dtype=np.float64).reshape(-1, 4)
    return q * np.array([1.0, -1.0, -1.0, -1.0])

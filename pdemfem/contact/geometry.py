"""Small vector operations the sub-models share (scalars in, scalars out: no arrays, so inlining them
costs no reference counting)."""
from __future__ import annotations

import math

from numba import njit


@njit(inline="always", cache=True)
def turn_into_tangent_plane(x, y, z, nx, ny, nz):
    """The vector (x, y, z) with its normal part removed and its length kept: a contact spring follows
    the contact's tangent plane as the normal n turns."""
    length_squared = x * x + y * y + z * z
    along_normal = x * nx + y * ny + z * nz
    x -= along_normal * nx
    y -= along_normal * ny
    z -= along_normal * nz
    new_length_squared = x * x + y * y + z * z
    if new_length_squared > 0.0:
        scale = math.sqrt(length_squared / new_length_squared)
        x *= scale
        y *= scale
        z *= scale
    return x, y, z


@njit(inline="always", cache=True)
def no_pull_off(coefficients, a, b, effective_radius):
    """The pull-off overlap and friction offset of a non-cohesive normal model: none."""
    return 0.0

"""Bounding-volume hierarchy over triangles: flat arrays, numba kernels, build once, refit often.

Layout (structure of arrays, node 0 is the root, children always follow their
parent, so refitting in reverse node order visits children first):

    node_min, node_max   (nodes, 3)  axis-aligned box of each node
    node_left, node_right (nodes,)   child nodes; -1 for a leaf
    node_start, node_count (nodes,)  a leaf's triangles: order[start:start + count]
    order                (triangles,) triangle indices grouped by leaf

Build: top-down median split of the triangle centroids along the longest axis of
their bounds, LEAF_SIZE triangles per leaf, O(n log^2 n).  Refit: recompute the
boxes bottom-up from the current vertices, O(n), topology unchanged -- exact for
any vertex motion (the boxes always bound their triangles), only the query cost
grows when the motion scrambles the tree; `BVH.refit` rebuilds when the summed
box area has grown by more than `rebuild_growth` (default 2x) since the build.

Query: every triangle whose exact distance to a sphere centre is at most
reach = radius + skin, as CSR lists (offsets, items) per sphere.
"""
from __future__ import annotations

import numpy as np
from numba import njit

from pdemfem.walls.triangle_contact import point_triangle_distance_squared

LEAF_SIZE = 4


@njit(cache=True)
def _triangle_boxes(vertices, triangles):
    count = triangles.shape[0]
    low = np.empty((count, 3))
    high = np.empty((count, 3))
    for t in range(count):
        for axis in range(3):
            a = vertices[triangles[t, 0], axis]
            b = vertices[triangles[t, 1], axis]
            c = vertices[triangles[t, 2], axis]
            low[t, axis] = min(a, min(b, c))
            high[t, axis] = max(a, max(b, c))
    return low, high


@njit(cache=True)
def build_bvh(vertices, triangles, leaf_size):
    """(node_min, node_max, node_left, node_right, node_start, node_count, order)."""
    count = triangles.shape[0]
    low, high = _triangle_boxes(vertices, triangles)
    centroid = 0.5 * (low + high)
    capacity = max(1, 2 * count)
    node_min = np.empty((capacity, 3))
    node_max = np.empty((capacity, 3))
    node_left = np.full(capacity, -1, dtype=np.int32)
    node_right = np.full(capacity, -1, dtype=np.int32)
    node_start = np.zeros(capacity, dtype=np.int32)
    node_count = np.zeros(capacity, dtype=np.int32)
    order = np.arange(count).astype(np.int32)
    if count == 0:
        node_min[0, :] = np.inf
        node_max[0, :] = -np.inf
        return node_min[:1], node_max[:1], node_left[:1], node_right[:1], node_start[:1], node_count[:1], order
    stack = np.empty(2 * 64 + capacity, dtype=np.int32)
    nodes = 1
    node_start[0] = 0
    node_count[0] = count
    stack[0] = 0
    top = 1
    values = np.empty(count)
    while top > 0:
        top -= 1
        node = stack[top]
        start = node_start[node]
        end = start + node_count[node]
        for axis in range(3):
            node_min[node, axis] = np.inf
            node_max[node, axis] = -np.inf
        centre_low = np.full(3, np.inf)
        centre_high = np.full(3, -np.inf)
        for k in range(start, end):
            t = order[k]
            for axis in range(3):
                node_min[node, axis] = min(node_min[node, axis], low[t, axis])
                node_max[node, axis] = max(node_max[node, axis], high[t, axis])
                centre_low[axis] = min(centre_low[axis], centroid[t, axis])
                centre_high[axis] = max(centre_high[axis], centroid[t, axis])
        if end - start <= leaf_size:
            continue
        split_axis = 0
        extent = centre_high[0] - centre_low[0]
        for axis in range(1, 3):
            if centre_high[axis] - centre_low[axis] > extent:
                extent = centre_high[axis] - centre_low[axis]
                split_axis = axis
        for k in range(start, end):
            values[k - start] = centroid[order[k], split_axis]
        permutation = np.argsort(values[:end - start], kind="mergesort")
        segment = order[start:end].copy()
        for k in range(end - start):
            order[start + k] = segment[permutation[k]]
        middle = start + (end - start) // 2
        left = nodes
        right = nodes + 1
        nodes += 2
        node_left[node] = left
        node_right[node] = right
        node_start[left] = start
        node_count[left] = middle - start
        node_start[right] = middle
        node_count[right] = end - middle
        stack[top] = right
        stack[top + 1] = left
        top += 2
    return (node_min[:nodes].copy(), node_max[:nodes].copy(), node_left[:nodes].copy(), node_right[:nodes].copy(),
            node_start[:nodes].copy(), node_count[:nodes].copy(), order)


@njit(cache=True)
def refit_bvh(node_min, node_max, node_left, node_right, node_start, node_count, order, vertices, triangles):
    """Recompute every box from the current vertices, children before parents. Returns the summed box area."""
    area = 0.0
    for node in range(node_min.shape[0] - 1, -1, -1):
        left = node_left[node]
        if left < 0:
            for axis in range(3):
                node_min[node, axis] = np.inf
                node_max[node, axis] = -np.inf
            for k in range(node_start[node], node_start[node] + node_count[node]):
                t = order[k]
                for corner in range(3):
                    v = triangles[t, corner]
                    for axis in range(3):
                        x = vertices[v, axis]
                        if x < node_min[node, axis]:
                            node_min[node, axis] = x
                        if x > node_max[node, axis]:
                            node_max[node, axis] = x
        else:
            right = node_right[node]
            for axis in range(3):
                node_min[node, axis] = min(node_min[left, axis], node_min[right, axis])
                node_max[node, axis] = max(node_max[left, axis], node_max[right, axis])
        ex = node_max[node, 0] - node_min[node, 0]
        ey = node_max[node, 1] - node_min[node, 1]
        ez = node_max[node, 2] - node_min[node, 2]
        if ex >= 0.0:
            area += ex * ey + ey * ez + ez * ex
    return area


@njit(cache=True)
def query_spheres(node_min, node_max, node_left, node_right, node_start, node_count, order, vertices, triangles,
                  centers, reach, first, last, offsets, items):
    """Triangles within reach[i] of centers[i] for i in [first, last) into CSR (offsets, items).

    Rows outside [first, last) are empty.  Writes at most len(items) entries and
    returns the number needed: call again with a larger `items` when it exceeds it.
    """
    stack = np.empty(128, dtype=np.int32)
    written = 0
    count = centers.shape[0]
    for i in range(0, first + 1):
        offsets[i] = 0
    for i in range(first, last):
        offsets[i] = written
        x = centers[i, 0]
        y = centers[i, 1]
        z = centers[i, 2]
        r = reach[i]
        r_squared = r * r
        top = 1
        stack[0] = 0
        while top > 0:
            top -= 1
            node = stack[top]
            if (x + r < node_min[node, 0] or x - r > node_max[node, 0] or y + r < node_min[node, 1]
                    or y - r > node_max[node, 1] or z + r < node_min[node, 2] or z - r > node_max[node, 2]):
                continue
            left = node_left[node]
            if left >= 0:
                stack[top] = node_right[node]
                stack[top + 1] = left
                top += 2
                continue
            for k in range(node_start[node], node_start[node] + node_count[node]):
                t = order[k]
                if point_triangle_distance_squared(x, y, z, vertices, triangles, t) <= r_squared:
                    if written < items.shape[0]:
                        items[written] = t
                    written += 1
    for i in range(max(last, first), count + 1):
        offsets[i] = written
    return written


@njit(cache=True)
def brute_force_spheres(vertices, triangles, centers, reach, first, last, offsets, items):
    """The same lists as `query_spheres`, testing every triangle (the reference and the benchmark's baseline)."""
    written = 0
    count = centers.shape[0]
    for i in range(0, first + 1):
        offsets[i] = 0
    for i in range(first, last):
        offsets[i] = written
        x = centers[i, 0]
        y = centers[i, 1]
        z = centers[i, 2]
        r_squared = reach[i] * reach[i]
        for t in range(triangles.shape[0]):
            if point_triangle_distance_squared(x, y, z, vertices, triangles, t) <= r_squared:
                if written < items.shape[0]:
                    items[written] = t
                written += 1
    for i in range(max(last, first), count + 1):
        offsets[i] = written
    return written


class BVH:
    """A BVH over a triangle set whose vertices may move (refit) while its topology stays."""

    def __init__(self, vertices, triangles, leaf_size: int = LEAF_SIZE, rebuild_growth: float = 2.0):
        self.triangles = np.ascontiguousarray(triangles, dtype=np.int32)
        self.leaf_size = int(leaf_size)
        self.rebuild_growth = float(rebuild_growth)
        self.builds = 0
        self.refits = 0
        self.build(vertices)

    def build(self, vertices) -> None:
        vertices = np.ascontiguousarray(vertices, dtype=np.float64)
        (self.node_min, self.node_max, self.node_left, self.node_right, self.node_start, self.node_count,
         self.order) = build_bvh(vertices, self.triangles, self.leaf_size)
        self.built_area = self._area(vertices)
        self.builds += 1

    def _area(self, vertices) -> float:
        return refit_bvh(self.node_min, self.node_max, self.node_left, self.node_right, self.node_start,
                         self.node_count, self.order, vertices, self.triangles)

    def refit(self, vertices) -> None:
        """Update the boxes to moved vertices; rebuild when the tree has degraded (area grown > rebuild_growth x)."""
        vertices = np.ascontiguousarray(vertices, dtype=np.float64)
        area = self._area(vertices)
        self.refits += 1
        if area > self.rebuild_growth * self.built_area:
            self.build(vertices)

    @property
    def node_total(self) -> int:
        return len(self.node_left)

    def query(self, vertices, centers, reach, first: int = 0, last=None, capacity_hint: int = 0):
        """CSR (offsets, items) of the triangles within reach[i] of centers[i], rows [first, last)."""
        centers = np.ascontiguousarray(centers, dtype=np.float64).reshape(-1, 3)
        reach = np.ascontiguousarray(reach, dtype=np.float64)
        last = len(centers) if last is None else int(last)
        offsets = np.zeros(len(centers) + 1, dtype=np.int64)
        items = np.empty(max(capacity_hint, 4 * (last - first), 16), dtype=np.int32)
        needed = query_spheres(self.node_min, self.node_max, self.node_left, self.node_right, self.node_start,
                               self.node_count, self.order, vertices, self.triangles, centers, reach, first, last,
                               offsets, items)
        if needed > len(items):
            items = np.empty(needed, dtype=np.int32)
            query_spheres(self.node_min, self.node_max, self.node_left, self.node_right, self.node_start,
                          self.node_count, self.order, vertices, self.triangles, centers, reach, first, last,
                          offsets, items)
        return offsets, items[:needed]


def brute_force_query(vertices, triangles, centers, reach, first: int = 0, last=None):
    """Reference candidate lists by testing every triangle against every sphere."""
    vertices = np.ascontiguousarray(vertices, dtype=np.float64)
    triangles = np.ascontiguousarray(triangles, dtype=np.int32)
    centers = np.ascontiguousarray(centers, dtype=np.float64).reshape(-1, 3)
    reach = np.ascontiguousarray(reach, dtype=np.float64)
    last = len(centers) if last is None else int(last)
    offsets = np.zeros(len(centers) + 1, dtype=np.int64)
    items = np.empty(max(16, 4 * (last - first)), dtype=np.int32)
    needed = brute_force_spheres(vertices, triangles, centers, reach, first, last, offsets, items)
    if needed > len(items):
        items = np.empty(needed, dtype=np.int32)
        brute_force_spheres(vertices, triangles, centers, reach, first, last, offsets, items)
    return offsets, items[:needed]

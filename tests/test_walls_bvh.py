"""BVH candidate search: equal to brute force, and refit equal to rebuild, on random triangle soups."""
from __future__ import annotations

import numpy as np
import pytest

from pdemfem.walls.bvh import BVH, brute_force_query


def random_soup(rng, count, size=1.0, edge=0.05):
    """`count` random triangles of edge ~`edge` in a cube of side `size` (a soup: no shared vertices)."""
    centres = rng.uniform(0.0, size, (count, 1, 3))
    vertices = (centres + rng.normal(0.0, edge, (count, 3, 3))).reshape(-1, 3)
    return vertices, np.arange(3 * count, dtype=np.int32).reshape(-1, 3)


def as_sets(offsets, items):
    return [set(items[offsets[i]:offsets[i + 1]].tolist()) for i in range(len(offsets) - 1)]


@pytest.mark.parametrize("count", [1, 7, 500, 3000])
def test_query_equals_brute_force(count):
    rng = np.random.default_rng(count)
    vertices, triangles = random_soup(rng, count)
    centers = rng.uniform(-0.1, 1.1, (400, 3))
    reach = rng.uniform(0.01, 0.08, 400)
    bvh = BVH(vertices, triangles)
    found = as_sets(*bvh.query(vertices, centers, reach))
    expected = as_sets(*brute_force_query(vertices, triangles, centers, reach))
    assert found == expected  # exact: both use the same exact point-triangle distance test
    assert sum(map(len, expected)) > 0 or count < 10


def test_query_of_a_row_range_leaves_other_rows_empty():
    rng = np.random.default_rng(3)
    vertices, triangles = random_soup(rng, 800)
    centers = rng.uniform(0.0, 1.0, (300, 3))
    reach = np.full(300, 0.06)
    bvh = BVH(vertices, triangles)
    offsets, items = bvh.query(vertices, centers, reach, 100, 200)
    full = as_sets(*brute_force_query(vertices, triangles, centers, reach))
    sets = as_sets(offsets, items)
    assert all(not s for s in sets[:100] + sets[200:])
    assert sets[100:200] == full[100:200]


def test_refit_after_moving_vertices_equals_rebuild():
    rng = np.random.default_rng(11)
    vertices, triangles = random_soup(rng, 2000)
    bvh = BVH(vertices, triangles, rebuild_growth=np.inf)  # never fall back to a rebuild
    centers = rng.uniform(0.0, 1.0, (500, 3))
    reach = rng.uniform(0.01, 0.05, 500)
    for _ in range(3):
        # Large random motion (up to 10 triangle sizes): the refit tree is poor but must stay exact.
        vertices = vertices + rng.normal(0.0, 0.1, vertices.shape)
        bvh.refit(vertices)
        refitted = as_sets(*bvh.query(vertices, centers, reach))
        rebuilt = as_sets(*BVH(vertices, triangles).query(vertices, centers, reach))
        assert refitted == rebuilt == as_sets(*brute_force_query(vertices, triangles, centers, reach))
    assert bvh.builds == 1 and bvh.refits == 3


def test_refit_rebuilds_when_the_tree_degrades():
    rng = np.random.default_rng(5)
    vertices, triangles = random_soup(rng, 1000)
    bvh = BVH(vertices, triangles)
    bvh.refit(vertices + 1e-3)  # a translation keeps the box areas: refit only
    assert bvh.builds == 1
    scrambled = vertices[rng.permutation(len(vertices))]  # triangles now span the whole cube
    bvh.refit(scrambled)
    assert bvh.builds == 2

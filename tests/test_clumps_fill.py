"""Sphere filling of closed surfaces (pdemfem.clumps.fill): a box and an ellipsoid written as STL here."""
from __future__ import annotations

import numpy as np
import pytest

from pdemfem.clumps.fill import enclosed_volume, fill_surface, fill_surface_file, inside_grid
from pdemfem.errors import MeshError


def box_mesh(low, high):
    low, high = np.asarray(low, float), np.asarray(high, float)
    vertices = np.array([[x, y, z] for x in (low[0], high[0]) for y in (low[1], high[1]) for z in (low[2], high[2])])
    # vertex index 4 ix + 2 iy + iz; faces listed counter-clockwise seen from outside
    quads = [(0, 1, 3, 2), (4, 6, 7, 5), (0, 4, 5, 1), (2, 3, 7, 6), (0, 2, 6, 4), (1, 5, 7, 3)]
    triangles = [tri for a, b, c, d in quads for tri in ((a, b, c), (a, c, d))]
    return vertices, np.array(triangles)


def ellipsoid_mesh(axes, rings=24, segments=48):
    """Latitude-longitude triangulation; its vertices lie on the ellipsoid, so the polyhedron is inside it."""
    vertices = [[0.0, 0.0, axes[2]]]
    for i in range(1, rings):
        theta = np.pi * i / rings
        for j in range(segments):
            phi = 2 * np.pi * j / segments
            vertices.append([axes[0] * np.sin(theta) * np.cos(phi), axes[1] * np.sin(theta) * np.sin(phi),
                             axes[2] * np.cos(theta)])
    vertices.append([0.0, 0.0, -axes[2]])
    triangles = [(0, 1 + j, 1 + (j + 1) % segments) for j in range(segments)]
    for i in range(rings - 2):
        for j in range(segments):
            a, b = 1 + i * segments + j, 1 + i * segments + (j + 1) % segments
            triangles += [(a, a + segments, b + segments), (a, b + segments, b)]
    base, last = 1 + (rings - 2) * segments, len(vertices) - 1
    triangles += [(last, base + (j + 1) % segments, base + j) for j in range(segments)]
    return np.array(vertices), np.array(triangles)


def write_stl(path, vertices, triangles):
    """Binary STL (float32 coordinates); returns the path and the surface as read back."""
    import meshio
    from pdemfem.walls.readers import read_surface
    meshio.write(str(path), meshio.Mesh(vertices, [("triangle", triangles)]), file_format="stl", binary=True)
    stored_vertices, stored_triangles = read_surface(path)
    return path, stored_vertices, stored_triangles.astype(np.int64)


def assert_balls_inside_convex(vertices, triangles, positions, radii):
    """Independent check for a convex polyhedron: a ball is inside iff n.(c - p) + r <= 0 for every face."""
    a, b, c = (vertices[triangles[:, k]] for k in range(3))
    normals = np.cross(b - a, c - a)
    normals /= np.linalg.norm(normals, axis=1)[:, None]
    centroid = vertices.mean(axis=0)
    normals *= np.sign(np.einsum("ij,ij->i", normals, a - centroid))[:, None]   # outward
    signed = np.einsum("fk,sfk->sf", normals, positions[:, None, :] - a[None, :, :])
    # The STL's float32 vertices (rounding 2^-24 relative) leave the polyhedron convex only to a few such
    # roundings of its size, and the face planes exact to that: bound 4 x 2^-24 x size (measured 1.3e-8
    # on the ellipsoid, 0 on the box).  Radii from the distance estimate instead of the exact distance
    # would protrude by up to h/2 = 1.6e-2.
    assert (signed + radii[:, None]).max() <= 4 * 2.0 ** -24 * np.ptp(vertices, axis=0).max()


def test_box_fill(tmp_path):
    vertices, triangles = box_mesh([0, 0, 0], [2, 1, 1])
    path, vertices, triangles = write_stl(tmp_path / "box.stl", vertices, triangles)
    fills = {n: fill_surface_file(path, n) for n in (1, 4, 16)}
    again = fill_surface_file(path, 16)
    assert np.array_equal(again.positions, fills[16].positions) and np.array_equal(again.radii, fills[16].radii)
    fill = fills[16]
    assert len(fill.radii) == 16
    h = fill.spacing
    assert fill.enclosed_volume == pytest.approx(2.0, rel=1e-15)
    assert_balls_inside_convex(vertices, triangles, fill.positions, fill.radii)
    # The two largest inscribed balls (r = 1/2, centred on the medial segment y = z = 1/2) come first, up to
    # the grid: a grid point lies within h sqrt(2)/2 of the segment.
    assert 0.5 - h <= fill.radii[0] <= 0.5 and 0.5 - h <= fill.radii[1] <= 0.5
    assert abs(fill.positions[1, 0] - fill.positions[0, 0]) >= 1.0 - h     # side by side, not stacked
    # More spheres cover more (the greedy adds new volume each round); measured 0.26, 0.64, 0.75.
    coverage = [fills[n].coverage for n in (1, 4, 16)]
    assert coverage[0] < coverage[1] < coverage[2] <= 1.0
    assert fills[1].coverage == pytest.approx(4 / 3 * np.pi * fills[1].radii[0] ** 3 / 2.0, rel=1e-14)


def test_ellipsoid_fill(tmp_path):
    axes = (1.0, 0.6, 0.4)
    vertices, triangles = ellipsoid_mesh(axes)
    path, vertices, triangles = write_stl(tmp_path / "ellipsoid.stl", vertices, triangles)
    fill = fill_surface_file(path, 32)
    again = fill_surface_file(path, 32)
    assert np.array_equal(again.positions, fill.positions) and np.array_equal(again.radii, fill.radii)
    assert len(fill.radii) == 32
    assert_balls_inside_convex(vertices, triangles, fill.positions, fill.radii)
    # The largest inscribed ball of the ellipsoid has the smallest semi-axis 0.4; the polyhedron is inside
    # the ellipsoid by at most 0.4 (1 - cos(pi/24)) = 3.4e-3 near the poles, and the centre is a grid point.
    assert 0.4 - 3.4e-3 - fill.spacing <= fill.radii[0] <= 0.4
    # Coverage grows with the count: measured 0.25 (1), 0.55 (4), 0.74 (16), 0.78 (32).
    fewer = fill_surface_file(path, 8)
    assert fewer.coverage < fill.coverage <= 1.0
    assert np.array_equal(fewer.radii, fill.radii[:8])      # greedy: a prefix of the longer fill
    # The reported coverage is union volume / enclosed volume.
    assert fill.coverage == pytest.approx(fill.union_volume / fill.enclosed_volume, rel=1e-15)
    assert fill.enclosed_volume == pytest.approx(4 / 3 * np.pi * np.prod(axes), rel=0.01)  # polyhedral: -0.2 %


def test_ray_parity_inside_grid_volume():
    """The inside set of the grid has the enclosed volume up to the boundary layer (area x h)."""
    axes = (1.0, 0.6, 0.4)
    vertices, triangles = ellipsoid_mesh(axes)
    a, b, c = (vertices[triangles[:, k]] for k in range(3))
    area = 0.5 * np.linalg.norm(np.cross(b - a, c - a), axis=1).sum()
    grid = inside_grid(vertices, triangles, cells=64)
    counted = grid.inside.sum() * grid.spacing ** 3
    # Only the points within ~h of the surface can be wrong in a cell count; their volume is area x h / 2
    # on either side, so the bound area x h is generous.  (Measured: 1e-4 relative, as the errors cancel.)
    assert abs(counted - enclosed_volume(vertices, triangles)) <= area * grid.spacing
    # Points well inside the ellipsoid's polyhedron are inside, points outside the ellipsoid are outside.
    points = grid.points()
    assert (((points / axes) ** 2).sum(axis=1) <= 1.0).all()


def test_open_surface_is_refused():
    vertices, triangles = box_mesh([0, 0, 0], [1, 1, 1])
    with pytest.raises(MeshError, match="not closed"):
        fill_surface(vertices, triangles[:-1], 4)

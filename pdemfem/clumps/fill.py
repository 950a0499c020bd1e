"""Fill a closed triangulated surface with N spheres, deterministically (the clump of a shape file).

Algorithm (greedy inscribed spheres on a distance map):

1. Grid: cubic cells of spacing h = (longest side of the surface's bounding box) / `cells`, one
   extra layer outside the box on each side, offset from the box by small irrational fractions of h
   (1e-3 sqrt 2, sqrt 3, sqrt 5) so that no grid line runs exactly through a mesh vertex or edge of
   axis-aligned or regularly tessellated shapes.
2. Inside test by ray parity: for each (x, y) grid column, the crossings of the vertical line with the
   triangles are collected (2-D barycentric test, z interpolated), sorted, and a grid point is inside
   when an odd number of crossings lies below it.  Needs a closed (watertight) surface, which is
   checked first: every edge must belong to exactly two triangles.
3. Distance map: the exact Euclidean distance transform of the inside set (Felzenszwalb &
   Huttenlocher's separable lower-envelope algorithm, O(grid)), i.e. the distance D of each inside
   point to the nearest outside grid point; the distance to the surface is D - h/2 within about h.
4. Greedy: candidates are the inside points with D - h/2 > 0 and that estimated radius r_c.  Each of
   the N rounds takes the candidate that adds the most new volume by the estimate
   4/3 pi r_c^3 - sum_i lens(candidate, sphere_i) (the pairwise lens volumes, a lower bound of the new
   volume; ties go to the lowest grid index, so the output is deterministic).  The estimate errs by
   up to about h, so the candidates within 2 h of the winner are rescored with their exact distance to
   the triangles (and the exact lenses) and the best of them is placed with that exact radius: every
   sphere lies inside the surface, and the first one is the largest inscribed sphere centred on a grid
   point (within about h of the true largest).  Later ones fill the remaining lobes and corners.
   Rounds stop early when no candidate adds volume (fewer spheres are returned).

Coverage reported: volume of the union of the spheres (pdemfem.clumps.shape, exact or ray grid)
over the enclosed volume (divergence theorem over the triangles).  Cost: O(cells^3) for the grid,
O(N cells^3 f) for the greedy rounds, where f is the inside fraction.
"""
from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np
from numba import njit

from pdemfem.clumps.shape import sphere_union_mass_properties
from pdemfem.errors import MeshError
from pdemfem.walls.readers import read_surface
from pdemfem.walls.triangle_contact import point_triangle_distance_squared

GRID_OFFSET = 1e-3 * np.sqrt([2.0, 3.0, 5.0])
FAR = 1e30   # "infinite" squared distance for the distance transform (finite: no inf - inf)


@dataclass(frozen=True)
class SphereFill:
    positions: np.ndarray      # (n, 3) sphere centres, the surface's frame
    radii: np.ndarray          # (n,)
    enclosed_volume: float     # volume inside the surface
    union_volume: float        # volume of the union of the spheres
    coverage: float            # union_volume / enclosed_volume (the spheres are inside: <= 1)
    spacing: float             # grid spacing h


def check_closed(triangles, where: str) -> None:
    """Every edge of a closed surface belongs to exactly two triangles."""
    triangles = np.asarray(triangles, dtype=np.int64)
    edges = np.sort(np.concatenate([triangles[:, [0, 1]], triangles[:, [1, 2]], triangles[:, [2, 0]]]), axis=1)
    _, counts = np.unique(edges, axis=0, return_counts=True)
    open_edges = int((counts != 2).sum())
    if open_edges:
        raise MeshError(where, f"the surface is not closed: {open_edges} edge(s) do not belong to exactly two "
                               "triangles", "give a watertight surface (close holes, remove duplicate faces)")


def enclosed_volume(vertices, triangles) -> float:
    """Volume inside a closed surface: |sum a . (b x c)| / 6 (either orientation)."""
    a, b, c = (vertices[triangles[:, k]] for k in range(3))
    return abs(float(np.einsum("ij,ij->", a, np.cross(b, c)))) / 6.0


@njit(cache=True)
def _column_crossings(vertices, triangles, origin, spacing, nx, ny, offsets, crossings, count_only):
    """Count (count_only) or store the z of the crossings of each grid column's vertical line."""
    fill = np.zeros(nx * ny, dtype=np.int64)
    for t in range(triangles.shape[0]):
        ax, ay, az = vertices[triangles[t, 0], 0], vertices[triangles[t, 0], 1], vertices[triangles[t, 0], 2]
        bx, by, bz = vertices[triangles[t, 1], 0], vertices[triangles[t, 1], 1], vertices[triangles[t, 1], 2]
        cx, cy, cz = vertices[triangles[t, 2], 0], vertices[triangles[t, 2], 1], vertices[triangles[t, 2], 2]
        area = (bx - ax) * (cy - ay) - (by - ay) * (cx - ax)
        if area == 0.0:
            continue   # parallel to the rays: never crossed
        i_low = max(0, int(math.ceil((min(ax, bx, cx) - origin[0]) / spacing)))
        i_high = min(nx - 1, int(math.floor((max(ax, bx, cx) - origin[0]) / spacing)))
        j_low = max(0, int(math.ceil((min(ay, by, cy) - origin[1]) / spacing)))
        j_high = min(ny - 1, int(math.floor((max(ay, by, cy) - origin[1]) / spacing)))
        for i in range(i_low, i_high + 1):
            x = origin[0] + i * spacing
            for j in range(j_low, j_high + 1):
                y = origin[1] + j * spacing
                wa = ((bx - x) * (cy - y) - (by - y) * (cx - x)) / area
                wb = ((cx - x) * (ay - y) - (cy - y) * (ax - x)) / area
                wc = 1.0 - wa - wb
                if wa < 0.0 or wb < 0.0 or wc < 0.0:
                    continue
                column = i * ny + j
                if not count_only:
                    crossings[offsets[column] + fill[column]] = wa * az + wb * bz + wc * cz
                fill[column] += 1
    return fill


@njit(cache=True)
def _classify_columns(crossings, offsets, origin_z, spacing, nz, inside):
    for column in range(offsets.shape[0] - 1):
        start, end = offsets[column], offsets[column + 1]
        if end == start:
            continue
        zs = np.sort(crossings[start:end])
        below = 0
        for k in range(nz):
            z = origin_z + k * spacing
            while below < zs.shape[0] and zs[below] < z:
                below += 1
            inside[column * nz + k] = below % 2 == 1


@njit(cache=True)
def _distance_transform_1d(f, n, out, hull, bounds):
    """Squared distance transform of one line (Felzenszwalb & Huttenlocher 2012, lower envelope of parabolas)."""
    k = 0
    hull[0] = 0
    bounds[0] = -FAR
    bounds[1] = FAR
    for q in range(1, n):
        s = ((f[q] + q * q) - (f[hull[k]] + hull[k] * hull[k])) / (2.0 * q - 2.0 * hull[k])
        while s <= bounds[k]:
            k -= 1
            s = ((f[q] + q * q) - (f[hull[k]] + hull[k] * hull[k])) / (2.0 * q - 2.0 * hull[k])
        k += 1
        hull[k] = q
        bounds[k] = s
        bounds[k + 1] = FAR
    k = 0
    for q in range(n):
        while bounds[k + 1] < q:
            k += 1
        out[q] = (q - hull[k]) * (q - hull[k]) + f[hull[k]]


@njit(cache=True)
def _squared_distance_to_outside(inside, nx, ny, nz):
    """Squared distance (in cells) of every grid point to the nearest outside grid point."""
    field = np.empty((nx, ny, nz))
    for i in range(nx):
        for j in range(ny):
            for k in range(nz):
                field[i, j, k] = FAR if inside[(i * ny + j) * nz + k] else 0.0
    longest = max(nx, ny, nz)
    line = np.empty(longest)
    out = np.empty(longest)
    hull = np.empty(longest, dtype=np.int64)
    bounds = np.empty(longest + 1)
    for j in range(ny):
        for k in range(nz):
            for i in range(nx):
                line[i] = field[i, j, k]
            _distance_transform_1d(line, nx, out, hull, bounds)
            for i in range(nx):
                field[i, j, k] = out[i]
    for i in range(nx):
        for k in range(nz):
            for j in range(ny):
                line[j] = field[i, j, k]
            _distance_transform_1d(line, ny, out, hull, bounds)
            for j in range(ny):
                field[i, j, k] = out[j]
    for i in range(nx):
        for j in range(ny):
            for k in range(nz):
                line[k] = field[i, j, k]
            _distance_transform_1d(line, nz, out, hull, bounds)
            for k in range(nz):
                field[i, j, k] = out[k]
    return field


@njit(cache=True)
def _lens_volume(d, r1, r2):
    """Volume of the intersection of two balls with centres d apart."""
    if d >= r1 + r2:
        return 0.0
    small = min(r1, r2)
    if d <= abs(r1 - r2):
        return 4.0 / 3.0 * math.pi * small ** 3
    return math.pi * (r1 + r2 - d) ** 2 * (d * d + 2.0 * d * (r1 + r2) - 3.0 * (r1 - r2) ** 2) / (12.0 * d)


@njit(cache=True)
def _distance_to_triangles(px, py, pz, vertices, triangles):
    nearest = np.inf
    for t in range(triangles.shape[0]):
        d2 = point_triangle_distance_squared(px, py, pz, vertices, triangles, t)
        if d2 < nearest:
            nearest = d2
    return math.sqrt(nearest)


@njit(cache=True)
def _greedy_spheres(candidates, candidate_radii, count, spacing, vertices, triangles, out_positions, out_radii):
    overlap = np.zeros(candidates.shape[0])
    placed = 0
    reach_squared = (2.0 * spacing) ** 2
    for _ in range(count):
        best = -1
        best_score = 0.0
        for c in range(candidates.shape[0]):
            score = 4.0 / 3.0 * math.pi * candidate_radii[c] ** 3 - overlap[c]
            if score > best_score:
                best_score = score
                best = c
        if best < 0:
            break
        # Refine: the estimate errs by up to about h, so score the candidates within 2 h of the best with
        # their exact distance to the surface and keep the best of those (ties: lowest grid index).
        chosen = -1
        chosen_score = 0.0
        chosen_radius = 0.0
        for c in range(candidates.shape[0]):
            dx = candidates[c, 0] - candidates[best, 0]
            dy = candidates[c, 1] - candidates[best, 1]
            dz = candidates[c, 2] - candidates[best, 2]
            if dx * dx + dy * dy + dz * dz > reach_squared:
                continue
            radius = _distance_to_triangles(candidates[c, 0], candidates[c, 1], candidates[c, 2], vertices, triangles)
            score = 4.0 / 3.0 * math.pi * radius ** 3
            for s in range(placed):
                ex = candidates[c, 0] - out_positions[s, 0]
                ey = candidates[c, 1] - out_positions[s, 1]
                ez = candidates[c, 2] - out_positions[s, 2]
                score -= _lens_volume(math.sqrt(ex * ex + ey * ey + ez * ez), radius, out_radii[s])
            if score > chosen_score:
                chosen_score = score
                chosen = c
                chosen_radius = radius
        if chosen < 0:
            break
        px, py, pz = candidates[chosen, 0], candidates[chosen, 1], candidates[chosen, 2]
        out_positions[placed, 0] = px
        out_positions[placed, 1] = py
        out_positions[placed, 2] = pz
        out_radii[placed] = chosen_radius
        placed += 1
        for c in range(candidates.shape[0]):
            dx = candidates[c, 0] - px
            dy = candidates[c, 1] - py
            dz = candidates[c, 2] - pz
            overlap[c] += _lens_volume(math.sqrt(dx * dx + dy * dy + dz * dz), candidate_radii[c], chosen_radius)
    return placed


@dataclass(frozen=True)
class InsideGrid:
    inside: np.ndarray     # (nx, ny, nz) bool
    origin: np.ndarray     # (3,) position of point (0, 0, 0)
    spacing: float

    def points(self, mask=None) -> np.ndarray:
        index = np.argwhere(self.inside if mask is None else mask)
        return self.origin + index * self.spacing


def inside_grid(vertices, triangles, cells: int = 64, where: str = "surface") -> InsideGrid:
    """Grid points inside a closed surface (steps 1-2 of the module docstring)."""
    vertices = np.ascontiguousarray(vertices, dtype=np.float64)
    triangles = np.ascontiguousarray(triangles, dtype=np.int64)
    check_closed(triangles, where)
    low, high = vertices.min(axis=0), vertices.max(axis=0)
    spacing = float((high - low).max()) / cells
    shape = np.ceil((high - low) / spacing).astype(np.int64) + 3
    origin = low - spacing + GRID_OFFSET * spacing
    nx, ny, nz = (int(v) for v in shape)
    empty = np.empty(0)
    counts = _column_crossings(vertices, triangles, origin, spacing, nx, ny, np.zeros(1, dtype=np.int64), empty, True)
    offsets = np.zeros(nx * ny + 1, dtype=np.int64)
    np.cumsum(counts, out=offsets[1:])
    crossings = np.empty(offsets[-1])
    _column_crossings(vertices, triangles, origin, spacing, nx, ny, offsets, crossings, False)
    inside = np.zeros(nx * ny * nz, dtype=np.bool_)
    _classify_columns(crossings, offsets, origin[2], spacing, nz, inside)
    return InsideGrid(inside.reshape(nx, ny, nz), origin, spacing)


def fill_surface(vertices, triangles, count: int, cells: int = 64, where: str = "surface") -> SphereFill:
    """Up to `count` spheres inside the closed surface (vertices (n, 3), triangles (m, 3))."""
    if int(count) < 1:
        raise MeshError(where, f"spheres must be at least 1, got {count}", "give the number of spheres to fill with")
    vertices = np.ascontiguousarray(vertices, dtype=np.float64)
    triangles = np.ascontiguousarray(triangles, dtype=np.int64)
    grid = inside_grid(vertices, triangles, cells, where)
    if not grid.inside.any():
        raise MeshError(where, "no grid point lies inside the surface", "give a closed surface, or more cells")
    nx, ny, nz = grid.inside.shape
    squared = _squared_distance_to_outside(grid.inside.reshape(-1), nx, ny, nz)
    estimate = np.sqrt(squared) * grid.spacing - 0.5 * grid.spacing
    usable = grid.inside & (estimate > 0.0)
    candidates = np.ascontiguousarray(grid.points(usable))
    candidate_radii = np.ascontiguousarray(estimate[usable])
    positions = np.empty((int(count), 3))
    radii = np.empty(int(count))
    placed = _greedy_spheres(candidates, candidate_radii, int(count), grid.spacing, vertices, triangles, positions, radii)
    positions, radii = positions[:placed], radii[:placed]
    volume = enclosed_volume(vertices, triangles)
    union = sphere_union_mass_properties(positions, radii, 1.0, where=where).mass
    return SphereFill(positions, radii, volume, union, union / volume, grid.spacing)


def fill_surface_file(path, count: int, scale: float = 1.0, cells: int = 64) -> SphereFill:
    """fill_surface of a surface mesh file (STL, .msh, ...; pdemfem.walls.readers.read_surface)."""
    vertices, triangles = read_surface(path, scale)
    return fill_surface(vertices, triangles, count, cells, where=str(path))

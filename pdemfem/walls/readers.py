"""Surface meshes from files: STL (ASCII or binary), gmsh .msh, and whatever else meshio reads.

Returns welded vertices and triangles; quadratic triangles (triangle6) are split
into four linear ones, quads into two.  Degenerate triangles (repeated vertex or
zero area) are dropped, unused vertices removed.
"""
from __future__ import annotations

from pathlib import Path

import numpy as np

from pdemfem.errors import MeshError


def read_surface(path, scale: float = 1.0):
    """(vertices (n, 3) float64, triangles (m, 3) int32) of the triangle cells of a mesh file, times `scale`."""
    import meshio

    path = Path(path)
    if not path.is_file():
        raise MeshError(str(path), "surface mesh file not found", "check the path (relative paths start at the scene file)")
    try:
        mesh = meshio.read(path)
    except Exception as error:  # meshio raises many kinds; all mean "cannot use this file"
        raise MeshError(str(path), f"cannot read the surface mesh ({type(error).__name__}: {error})",
                        "give an STL, gmsh .msh or another meshio-readable surface mesh") from None
    blocks = []
    for block in mesh.cells:
        data = np.asarray(block.data, dtype=np.int64)
        if block.type == "triangle":
            blocks.append(data)
        elif block.type == "triangle6":
            # Corner nodes 0-2, mid-edge nodes 3 (01), 4 (12), 5 (20): four linear triangles.
            a, b, c, ab, bc, ca = (data[:, k] for k in range(6))
            blocks.append(np.concatenate([np.stack(t, axis=1) for t in
                                          ((a, ab, ca), (ab, b, bc), (ca, bc, c), (ab, bc, ca))]))
        elif block.type == "quad":
            blocks.append(np.concatenate([data[:, [0, 1, 2]], data[:, [0, 2, 3]]]))
    if not blocks:
        types = sorted({block.type for block in mesh.cells})
        raise MeshError(str(path), f"no triangles in the mesh (cell types: {types or 'none'})",
                        "export the surface as triangles (in gmsh: mesh 2D and save the surface elements)")
    triangles = np.concatenate(blocks)
    points = np.asarray(mesh.points, dtype=np.float64)
    if points.shape[1] == 2:
        points = np.column_stack([points, np.zeros(len(points))])
    points = points[:, :3] * float(scale)
    # One NaN vertex would make the welding and the BVH treat the whole surface as absent:
    # every particle falls through the wall.
    used = np.unique(triangles)
    bad = used[~np.isfinite(points[used]).all(axis=1)]
    if len(bad):
        raise MeshError(str(path), f"{len(bad)} vertex(es) have a NaN or infinite coordinate (first: vertex "
                                   f"{int(bad[0])} at {points[bad[0]].tolist()}"
                                   + (f" after scale {scale:g}" if scale != 1.0 else "") + ")",
                        "repair or re-export the surface mesh")
    return clean_surface(points, triangles)


def clean_surface(vertices, triangles):
    """Weld coincident vertices (STL stores every corner separately), drop degenerate triangles and unused vertices."""
    vertices = np.ascontiguousarray(vertices, dtype=np.float64)
    triangles = np.asarray(triangles, dtype=np.int64)
    # Weld vertices closer than 1e-10 of the mesh size (snapped keys; the first copy's coordinates are kept).
    size = float(np.ptp(vertices, axis=0).max()) if len(vertices) else 1.0
    quantum = max(size, 1e-300) * 1e-10
    keys = np.round(vertices / quantum).astype(np.int64)
    _, first, inverse = np.unique(keys, axis=0, return_index=True, return_inverse=True)
    unique = vertices[first]
    triangles = inverse.reshape(-1)[triangles]
    distinct = ((triangles[:, 0] != triangles[:, 1]) & (triangles[:, 1] != triangles[:, 2])
                & (triangles[:, 2] != triangles[:, 0]))
    triangles = triangles[distinct]
    a, b, c = (unique[triangles[:, k]] for k in range(3))
    area2 = np.linalg.norm(np.cross(b - a, c - a), axis=1)
    size = max(size, 1e-300)
    triangles = triangles[area2 > 1e-14 * size * size]
    used = np.unique(triangles)
    renumber = np.full(len(unique), -1, dtype=np.int64)
    renumber[used] = np.arange(len(used))
    return np.ascontiguousarray(unique[used]), np.ascontiguousarray(renumber[triangles], dtype=np.int32)

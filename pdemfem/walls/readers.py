"""Surface meshes from files: STL (ASCII or binary), gmsh .msh, a gmsh .geo file (meshed in 2-D in
memory), and whatever else meshio reads.

Returns welded vertices and triangles; quadratic triangles (triangle6) are split
into four linear ones, quads into two.  Degenerate triangles (repeated vertex or
zero area) are dropped, unused vertices removed.
"""
from __future__ import annotations

from pathlib import Path

import numpy as np

from pdemfem.errors import MeshError
from pdemfem.gmsh_geo import gmsh_session, mesh_geo_file

# gmsh's element type names -> meshio's, for the surface cells the readers split into triangles.
GMSH_SURFACE_TYPES = {"triangle 3": "triangle", "triangle 6": "triangle6", "quadrilateral 4": "quad"}


def read_surface(path, scale: float = 1.0):
    """(vertices (n, 3) float64, triangles (m, 3) int32) of the triangle cells of a mesh file, times `scale`."""
    path = Path(path)
    if path.is_dir():
        raise MeshError(str(path), "is a directory, not a surface mesh file",
                        "give the mesh file itself (STL, gmsh .msh or .geo), relative to the scene file")
    if not path.is_file():
        raise MeshError(str(path), "surface mesh file not found", "check the path (relative paths start at the scene file)")
    if path.suffix.lower() == ".geo":
        points, cells = _mesh_geo_surface(path)
    else:
        points, cells = _read_meshio_surface(path)
    blocks = []
    for cell_type, data in cells:
        data = np.asarray(data, dtype=np.int64)
        if cell_type == "triangle":
            blocks.append(data)
        elif cell_type == "triangle6":
            # Corner nodes 0-2, mid-edge nodes 3 (01), 4 (12), 5 (20): four linear triangles.
            a, b, c, ab, bc, ca = (data[:, k] for k in range(6))
            blocks.append(np.concatenate([np.stack(t, axis=1) for t in
                                          ((a, ab, ca), (ab, b, bc), (ca, bc, c), (ab, bc, ca))]))
        elif cell_type == "quad":
            blocks.append(np.concatenate([data[:, [0, 1, 2]], data[:, [0, 2, 3]]]))
    if not blocks:
        types = sorted({cell_type for cell_type, _ in cells})
        raise MeshError(str(path), f"no triangles in the mesh (cell types: {types or 'none'})",
                        "export the surface as triangles (in gmsh: mesh 2D and save the surface elements)")
    triangles = np.concatenate(blocks)
    points = np.asarray(points, dtype=np.float64)
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


STL_HEADER = 84         # binary STL: an 80-byte header and a uint32 triangle count,
STL_TRIANGLE = 50       # then 50 bytes per triangle (normal, three corners, attribute word)


def stl_problem(path: Path):
    """None for a plausible STL file, else (problem, fix): a binary STL whose size does not match the
    triangle count in its header (cut short by an interrupted copy or export), or a file that is neither
    a binary STL nor text (an ASCII STL starts with 'solid')."""
    size = path.stat().st_size
    with open(path, "rb") as handle:
        head = handle.read(1024)
    count = int(np.frombuffer(head[80:STL_HEADER], dtype="<u4")[0]) if size >= STL_HEADER else None
    if count is not None and size == STL_HEADER + STL_TRIANGLE * count:
        return None  # a whole binary STL (its header may start with 'solid' too)
    if head.lstrip()[:5].lower() == b"solid":
        try:
            head.decode("ascii")
        except UnicodeDecodeError:
            pass
        else:
            # An ASCII STL: meshio reports a line cut in the middle, but one cut between two facets reads as a
            # smaller surface.  Its last line must close the solid.
            with open(path, "rb") as handle:
                handle.seek(max(size - 1024, 0))
                lines = handle.read().rstrip().splitlines()
            if lines and lines[-1].lstrip().lower().startswith(b"endsolid"):
                return None
            return ("an ASCII STL cut short: its last line is not 'endsolid' (the facets after the cut are "
                    "missing)", "the file was truncated (an interrupted copy, download or export): copy or export "
                    "it again")
    if size == 0:
        return "the file is empty (0 bytes)", "export the surface again (STL, gmsh .msh or .geo)"
    if count is None:
        return (f"is {size} bytes: too short for a binary STL ({STL_HEADER}-byte header with the triangle count) "
                f"and not an ASCII STL (which starts with 'solid')", "export the surface again as STL")
    expected = STL_HEADER + STL_TRIANGLE * count
    if size < expected and expected > 16 * size:
        return (f"not an STL file: read as a binary STL its header announces {count} triangles ({expected} bytes), "
                f"far more than the file's {size} bytes, and it is not an ASCII STL (which starts with 'solid')",
                "check that this is the right file (a surface mesh saved as STL), or export the surface again")
    if size < expected:
        whole = (size - STL_HEADER) // STL_TRIANGLE
        return (f"a binary STL cut short: its header announces {count} triangles ({expected} bytes) but the file "
                f"has {size} bytes ({whole} whole triangles)",
                "the file was truncated (an interrupted copy, download or export): copy or export it again")
    return (f"not a valid STL: as a binary STL its header announces {count} triangles ({expected} bytes) but the "
            f"file has {size} bytes, and it is not an ASCII STL (which starts with 'solid')",
            "check that this is the right file, or export the surface again as STL")


def _read_meshio_surface(path: Path):
    """(points, [(meshio cell type, connectivity)]) of a mesh file meshio reads."""
    import meshio

    if path.stat().st_size == 0:
        raise MeshError(str(path), "the file is empty (0 bytes)",
                        "export the surface again (STL, gmsh .msh or .geo); an interrupted copy leaves such files")
    if path.suffix.lower() == ".stl":
        problem = stl_problem(path)
        if problem is not None:
            raise MeshError(str(path), *problem)
    try:
        mesh = meshio.read(path)
    except UnicodeDecodeError as error:  # a binary file read as text (ASCII STL, .obj, .vtk ...)
        kind = path.suffix or "no suffix"
        raise MeshError(str(path), f"cannot read the surface mesh: it is read as a text format ({kind}) but holds "
                                   f"binary data at byte {error.start}",
                        "check that the file is the surface mesh its suffix says (re-export it), or give an STL, "
                        "gmsh .msh or .geo") from None
    except Exception as error:  # meshio raises many kinds; all mean "cannot use this file"
        raise MeshError(str(path), f"cannot read the surface mesh ({type(error).__name__}: {error})",
                        "give an STL, gmsh .msh or .geo, or another meshio-readable surface mesh") from None
    return mesh.points, [(block.type, block.data) for block in mesh.cells]


def _mesh_geo_surface(path: Path):
    """(points, [(meshio cell type, connectivity)]) of a .geo file's surfaces meshed in 2-D by gmsh: the
    surfaces of its 2-D physical groups if it has any (what a .msh saved from it would hold), else all."""
    import gmsh

    cells = []
    with gmsh_session():
        mesh_geo_file(path, 2)
        node_tags, coordinates, _ = gmsh.model.mesh.getNodes()
        grouped = {entity for dim, tag in gmsh.model.getPhysicalGroups(2)
                   for entity in gmsh.model.getEntitiesForPhysicalGroup(dim, tag)}
        surfaces = sorted(int(entity) for entity in grouped) or [tag for _, tag in gmsh.model.getEntities(2)]
        order = np.argsort(node_tags)
        sorted_tags = node_tags[order]
        for surface in surfaces:
            for element_type, _, nodes in zip(*gmsh.model.mesh.getElements(2, surface)):
                name, _, _, n_nodes = gmsh.model.mesh.getElementProperties(element_type)[:4]
                cell_type = GMSH_SURFACE_TYPES.get(f"{name.split()[0].lower()} {n_nodes}", name)
                connectivity = np.searchsorted(sorted_tags, nodes).reshape(-1, n_nodes)
                cells.append((cell_type, connectivity))
        gmsh.model.remove()
    return coordinates.reshape(-1, 3)[order], cells


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

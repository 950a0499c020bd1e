"""The global (serial) tetrahedral mesh: read with meshio, mesh a gmsh .geo file or generate a box with gmsh,
check, name groups.

Runs on one rank (the partitioner distributes the result).  Groups are sets of
boundary triangles given as corner triples oriented with the outward normal.
Box faces xmin..zmax are available on every mesh as the boundary triangles lying
on the bounding box's planes.
"""
from __future__ import annotations

import contextlib
import io
from dataclasses import dataclass, field
from pathlib import Path

import numpy as np

from pdemfem.errors import MeshError
from pdemfem.fem.config import BOX_FACES, BoxMeshConfig
from pdemfem.gmsh_geo import gmsh_session, mesh_geo_file, note_read_failure

# Faces of a positively oriented tetrahedron, each listed counter-clockwise seen from outside.
OUTWARD_FACES = np.array([[0, 2, 1], [0, 1, 3], [0, 3, 2], [1, 2, 3]], dtype=np.int64)
# A cell whose volume is below this fraction of (longest edge)^3 / 6 is degenerate.
DEGENERATE_QUALITY = 1e-8


@dataclass
class GlobalMesh:
    source: str  # the file (or box description) named in error messages
    points: np.ndarray  # (n, 3) float64
    tets: np.ndarray  # (nc, 4) int64 corner connectivity, positive volume
    face_groups: dict = field(default_factory=dict)  # name -> (nf, 3) int64 outward-oriented corner triples

    def group_faces(self, name: str) -> np.ndarray:
        """The faces of a named group (file group first, then box face); MeshError if unknown."""
        if name in self.face_groups:
            return self.face_groups[name]
        if name in BOX_FACES:
            faces = box_face(self.points, boundary_faces(self.tets), name)
            if len(faces) == 0:
                raise MeshError(
                    where=f"{self.source}: group '{name}'",
                    problem="no boundary triangle lies on that face of the bounding box",
                    fix="use a physical group name of the mesh instead",
                )
            return faces
        raise MeshError(
            where=f"{self.source}: group '{name}'",
            problem=f"the mesh has no such group (groups: {sorted(self.face_groups)}; box faces: {list(BOX_FACES)})",
            fix="add a 2-D physical group with this name in gmsh, or correct the name in the scene",
        )


def load_mesh(spec, base_dir: Path) -> GlobalMesh:
    """A mesh from the scene's `mesh:` value (file path relative to base_dir, or BoxMeshConfig)."""
    if isinstance(spec, BoxMeshConfig):
        mesh = generate_box_mesh(spec)
        check_cells(mesh)
        return mesh
    path = Path(spec)
    if not path.is_absolute():
        path = Path(base_dir) / path
    return read_mesh_file(path)  # (its cells checked as it is assembled)


def generate_box_mesh(spec: BoxMeshConfig) -> GlobalMesh:
    """Structured (transfinite) box: nx*ny*nz hexahedra split into 6 tetrahedra each, by gmsh."""
    import gmsh

    low, high = np.array(spec.box[0], float), np.array(spec.box[1], float)
    with gmsh_session():
        gmsh.model.add("pdemfem_box")
        volume = gmsh.model.occ.addBox(*low, *(high - low))
        gmsh.model.occ.synchronize()
        for _, curve in gmsh.model.getEntities(1):
            bounds = np.array(gmsh.model.getBoundingBox(1, curve))
            axis = int(np.argmax(bounds[3:] - bounds[:3]))
            gmsh.model.mesh.setTransfiniteCurve(curve, spec.cells[axis] + 1)
        for _, surface in gmsh.model.getEntities(2):
            gmsh.model.mesh.setTransfiniteSurface(surface)
        gmsh.model.mesh.setTransfiniteVolume(volume)
        gmsh.model.mesh.generate(3)
        node_tags, coordinates, _ = gmsh.model.mesh.getNodes()
        _, _, element_nodes = gmsh.model.mesh.getElements(3, volume)
        gmsh.model.remove()
    order = np.argsort(node_tags)
    points = coordinates.reshape(-1, 3)[order]
    tets = np.searchsorted(node_tags[order], element_nodes[0]).reshape(-1, 4).astype(np.int64)
    source = f"box {spec.box} cells {list(spec.cells)}"
    return GlobalMesh(source=source, points=points, tets=tets)


def read_mesh_file(path: Path) -> GlobalMesh:
    """Tetrahedra and named triangle groups: gmsh .msh through the gmsh API, a gmsh .geo file meshed in
    3-D by gmsh in memory, other formats through meshio."""
    source = str(path)
    if not path.is_file():
        raise MeshError(where=source, problem="file not found", fix="check the path (relative to the scene file)")
    if path.suffix.lower() in (".msh", ".geo"):
        # meshio keeps one physical tag per element, so a triangle in two groups ('boundary' and
        # 'bottom') would lose one; gmsh's own reader keeps every group.
        points, tets, triangle_groups = _read_gmsh_file(path)
    else:
        points, tets, triangle_groups = _read_meshio_file(path)
    return _assemble_global_mesh(source, points, tets, triangle_groups)


def require_finite_points(source, points: np.ndarray, numbers=None) -> None:
    """MeshError naming the first node with a NaN or infinite coordinate (it would poison every
    element and contact it belongs to)."""
    bad = np.flatnonzero(~np.isfinite(points).all(axis=1))
    if len(bad):
        first = int(bad[0])
        number = int(numbers[first]) if numbers is not None else first
        raise MeshError(where=source,
                        problem=f"{len(bad)} node(s) have a NaN or infinite coordinate (first: node {number} at "
                                f"{points[first].tolist()})",
                        fix="repair or re-export the mesh")


def _no_volume_error(source, other_volume=(), with_tetrahedra=False):
    problem = "the mesh has no volume cells (tetrahedra)"
    if other_volume:
        problem = f"the mesh's volume cells are {sorted(other_volume)}; only tetrahedra are supported"
    if with_tetrahedra:
        # Dropping them would lose that part of the solid (its mass, stiffness and supports) without a word.
        problem = (f"the mesh mixes tetrahedra with other volume cells ({', '.join(sorted(other_volume))}); only "
                   f"tetrahedra are supported")
    if source.lower().endswith(".geo"):
        fix = "define the solid's volume in the .geo file (a Volume, e.g. Box or Extrude) and do not recombine it"
        return MeshError(where=source, problem=problem, fix=fix)
    return MeshError(where=source, problem=problem, fix="mesh the volume (gmsh: Mesh > 3D) with tetrahedra and save again")


def _read_gmsh_file(path: Path):
    import gmsh

    source = str(path)
    with gmsh_session():
        if path.suffix.lower() == ".geo":
            mesh_geo_file(path, 3)
        else:
            try:
                gmsh.open(source)
            except Exception as exc:
                note_read_failure()  # gmsh parses a file it cannot read as .msh as a script
                raise MeshError(where=source, problem=f"cannot read the mesh ({exc})",
                                fix="export it from gmsh as .msh (format 4.1 or 2.2)") from None
        node_tags, coordinates, _ = gmsh.model.mesh.getNodes()
        order = np.argsort(node_tags)
        sorted_tags = node_tags[order]
        points = coordinates.reshape(-1, 3)[order]
        tet_parts, other_volume = [], set()
        for volume in _saved_volumes():
            for element_type, _, nodes in zip(*gmsh.model.mesh.getElements(3, volume)):
                name, _, _, n_nodes, _, n_corners = gmsh.model.mesh.getElementProperties(element_type)
                if name.lower().startswith("tetrahedron"):
                    tet_parts.append(nodes.reshape(-1, n_nodes)[:, :4])
                else:
                    other_volume.add(name)
        if not tet_parts or other_volume:
            raise _no_volume_error(source, other_volume, with_tetrahedra=bool(tet_parts))
        tets = np.searchsorted(sorted_tags, np.vstack(tet_parts)).astype(np.int64)
        groups = {}
        for dim, tag in gmsh.model.getPhysicalGroups(2):
            name = gmsh.model.getPhysicalName(dim, tag) or str(tag)
            parts = []
            for entity in gmsh.model.getEntitiesForPhysicalGroup(dim, tag):
                for element_type, _, nodes in zip(*gmsh.model.mesh.getElements(2, entity)):
                    element_name, _, _, n_nodes, _, _ = gmsh.model.mesh.getElementProperties(element_type)
                    if not element_name.lower().startswith("triangle"):
                        raise MeshError(where=f"{source}: group '{name}'",
                                        problem=f"its surface cells are {element_name}; only triangles are supported",
                                        fix="mesh the surfaces with triangles (no Recombine) and save again")
                    parts.append(nodes.reshape(-1, n_nodes)[:, :3])
            if parts:
                groups[name] = np.searchsorted(sorted_tags, np.vstack(parts)).astype(np.int64)
        gmsh.model.remove()
    return points, tets, groups


def _saved_volumes() -> list:
    """The volumes whose cells a .msh saved from gmsh's current model would hold: those of the 3-D physical
    groups if there are any (gmsh saves only grouped elements), else every volume.  A .geo file meshed in
    memory so gives the cells of the .msh made from it; a .msh read back holds only those volumes anyway."""
    import gmsh

    grouped = {entity for dim, tag in gmsh.model.getPhysicalGroups(3)
               for entity in gmsh.model.getEntitiesForPhysicalGroup(dim, tag)}
    if grouped:
        return sorted(int(entity) for entity in grouped)
    return [tag for _, tag in gmsh.model.getEntities(3)]


def _read_meshio_file(path: Path):
    import meshio

    source = str(path)
    chatter = io.StringIO()
    try:
        # meshio prints and even calls sys.exit on some malformed files: keep both inside this error
        with contextlib.redirect_stdout(chatter), contextlib.redirect_stderr(chatter):
            data = meshio.read(path)
    except (Exception, SystemExit) as exc:
        detail = " ".join(chatter.getvalue().split()) or f"{type(exc).__name__}: {exc}"
        raise MeshError(where=source, problem=f"cannot read the mesh ({detail})",
                        fix="export it from gmsh as .msh (format 4.1 or 2.2) or another meshio format") from None
    tet_blocks = [block.data[:, :4] for block in data.cells if block.type in ("tetra", "tetra10")]
    other_volume = {block.type for block in data.cells if block.type in ("hexahedron", "wedge", "pyramid", "hexahedron20", "hexahedron27")}
    if not tet_blocks or other_volume:
        raise _no_volume_error(source, other_volume, with_tetrahedra=bool(tet_blocks))
    points = np.asarray(data.points, dtype=float)
    if points.shape[1] != 3:
        raise MeshError(where=source, problem="points are not 3-D", fix="export a 3-D mesh")
    return points, np.vstack(tet_blocks).astype(np.int64), _named_triangle_sets(data)


def _assemble_global_mesh(source, points, tets, triangle_groups) -> GlobalMesh:
    """Drop nodes no cell uses, orient cells, match group triangles to cell faces."""
    used = np.unique(tets)
    renumber = np.full(len(points), -1, dtype=np.int64)
    renumber[used] = np.arange(len(used))
    require_finite_points(source, points[used], used)
    points = points[used]
    tets = renumber[tets]
    groups = {}
    for name, triangles in triangle_groups.items():
        triangles = renumber[triangles]
        if np.any(triangles < 0):
            raise MeshError(
                where=f"{source}: group '{name}'",
                problem="some of its triangles use nodes that belong to no tetrahedron",
                fix="make the group's surfaces part of the meshed volume's boundary",
            )
        groups[name] = triangles
    mesh = GlobalMesh(source=source, points=points, tets=tets)
    mesh.tets = _oriented_cells(mesh)
    check_cells(mesh)  # before the groups: a cell with a repeated node read as a group's missing face
    for name, triangles in groups.items():
        mesh.face_groups[name] = orient_faces(mesh, triangles, name)
    return mesh


def _named_triangle_sets(data) -> dict:
    """name -> (nf,3) node triples of 2-D groups, from gmsh physical names (or numeric tags)."""
    names_by_tag = {}
    for name, value in (data.field_data or {}).items():
        value = np.atleast_1d(value)
        if len(value) >= 2 and int(value[1]) == 2:
            names_by_tag[int(value[0])] = name
    found: dict = {}
    physical = (data.cell_data or {}).get("gmsh:physical")
    if physical is not None:
        for block, tags in zip(data.cells, physical):
            if block.type not in ("triangle", "triangle6"):
                continue
            for tag in np.unique(tags):
                name = names_by_tag.get(int(tag), str(int(tag)))
                found.setdefault(name, []).append(block.data[tags == tag, :3])
    else:
        for name, per_block in (data.cell_sets or {}).items():
            for block, indices in zip(data.cells, per_block):
                if block.type in ("triangle", "triangle6") and indices is not None and len(indices):
                    found.setdefault(name, []).append(block.data[np.asarray(indices), :3])
    return {name: np.vstack(parts).astype(np.int64) for name, parts in found.items()}


def signed_volumes(points: np.ndarray, tets: np.ndarray) -> np.ndarray:
    edges = points[tets[:, 1:]] - points[tets[:, [0]]]
    return np.linalg.det(edges) / 6.0


def _oriented_cells(mesh: GlobalMesh) -> np.ndarray:
    """A file whose every cell is negatively oriented is a convention, not an error: flip them all."""
    volumes = signed_volumes(mesh.points, mesh.tets)
    if np.all(volumes < 0):
        return mesh.tets[:, [0, 2, 1, 3]].copy()
    return mesh.tets


def check_cells(mesh: GlobalMesh) -> None:
    """MeshError for degenerate (near-zero volume) or inverted (negative volume) cells."""
    volumes = signed_volumes(mesh.points, mesh.tets)
    corners = mesh.points[mesh.tets]
    longest = np.zeros(len(mesh.tets))
    for i in range(4):
        for j in range(i + 1, 4):
            longest = np.maximum(longest, np.linalg.norm(corners[:, i] - corners[:, j], axis=1))
    quality = 6.0 * np.abs(volumes) / np.maximum(longest, np.finfo(float).tiny) ** 3
    degenerate = np.flatnonzero(quality < DEGENERATE_QUALITY)
    if len(degenerate):
        raise MeshError(
            where=f"{mesh.source}: cells {degenerate[:10].tolist()}{' ...' if len(degenerate) > 10 else ''}",
            problem=f"{len(degenerate)} degenerate cell(s) with (near) zero volume (quality {quality[degenerate].min():.1e})",
            fix="remesh; check for duplicate or collinear nodes",
        )
    inverted = np.flatnonzero(volumes < 0)
    if len(inverted):
        raise MeshError(
            where=f"{mesh.source}: cells {inverted[:10].tolist()}{' ...' if len(inverted) > 10 else ''}",
            problem=f"{len(inverted)} of {len(volumes)} cells are inverted (negative volume)",
            fix="remesh, or repair the cells' node order (gmsh: Mesh > Reverse)",
        )


def all_cell_faces(tets: np.ndarray) -> np.ndarray:
    """(4*nc, 3) outward-oriented faces of every cell."""
    return tets[:, OUTWARD_FACES].reshape(-1, 3)


def _face_keys(faces: np.ndarray, n_points: int) -> np.ndarray:
    s = np.sort(faces, axis=1)
    return (s[:, 0] * n_points + s[:, 1]) * n_points + s[:, 2]


def boundary_faces(tets: np.ndarray) -> np.ndarray:
    """Outward-oriented faces that belong to exactly one cell."""
    faces = all_cell_faces(tets)
    n = int(tets.max()) + 1
    keys = _face_keys(faces, n)
    _, first, counts = np.unique(keys, return_index=True, return_counts=True)
    return faces[np.sort(first[counts == 1])]


def orient_faces(mesh: GlobalMesh, triangles: np.ndarray, name: str) -> np.ndarray:
    """Match triangles to cell faces and return them with the cell's outward orientation."""
    faces = all_cell_faces(mesh.tets)
    n = len(mesh.points)
    keys = _face_keys(faces, n)
    order = np.argsort(keys, kind="stable")
    sorted_keys = keys[order]
    wanted = _face_keys(triangles, n)
    where = np.searchsorted(sorted_keys, wanted)
    where = np.minimum(where, len(sorted_keys) - 1)
    missing = sorted_keys[where] != wanted
    if np.any(missing):
        raise MeshError(
            where=f"{mesh.source}: group '{name}'",
            problem=f"{int(missing.sum())} of its triangles are not faces of any tetrahedron",
            fix="regenerate the mesh so surface and volume meshes are conforming",
        )
    return faces[order[where]]


def box_face(points: np.ndarray, boundary: np.ndarray, name: str) -> np.ndarray:
    """Boundary faces lying on the bounding-box plane `name` (xmin..zmax)."""
    axis = "xyz".index(name[0])
    low, high = points.min(axis=0), points.max(axis=0)
    tolerance = 1e-9 * float(np.linalg.norm(high - low))
    plane = low[axis] if name.endswith("min") else high[axis]
    on_plane = np.all(np.abs(points[boundary][:, :, axis] - plane) <= tolerance, axis=1)
    return boundary[on_plane]

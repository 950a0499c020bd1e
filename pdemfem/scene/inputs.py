"""Checks that need the built inputs (inserted particles, wall meshes), shared by `check` and `run`.

The schema validates each key on its own; these checks relate keys to each other and to
what the files and the insertion produce, so a scene that would lose its particles at step 0
or compute garbage is refused before anything runs:

    validate_geometry(scene, inserted, wall_vertices)   # raises SceneError

* coordinates: every particle position, plane/cylinder point, domain corner and mesh-wall vertex
  lies within COORDINATE_LIMIT_RADII smallest radii of the origin.  A float64 coordinate x is
  resolved to |x| * 2^-52; at 1e9 radii that is 2.2e-7 of a radius, still below the smallest
  contact overlaps (1e-6..1e-2 radii), while beyond it the overlaps round away and the cell grid
  (extent / cell size cells per axis) overflows.
* domain.box: no particle starts with its centre outside the box along a non-periodic axis (the
  run would remove it as lost at step 0).
* periodic axes: the period exceeds twice the interaction cutoff (largest diameter + skin), the
  same bound the particle system enforces, else a particle would meet its own image.
"""
from __future__ import annotations

import re
from contextlib import contextmanager

import numpy as np

from pdemfem.errors import MeshError, SceneError

COORDINATE_LIMIT_RADII = 1.0e9

# Same default as the run (pdemfem.simulation.DEFAULT_SKIN_FRACTION): the skin a scene gets when it
# names none, as a fraction of the smallest radius.
DEFAULT_SKIN_FRACTION = 0.3


def interaction_cutoff(scene, radii: np.ndarray) -> float:
    """Largest diameter + skin: how far apart two particle centres can interact before a rebuild."""
    if not len(radii):
        return 0.0
    skin = scene.neighbors.skin or DEFAULT_SKIN_FRACTION * float(radii.min())
    return 2.0 * float(radii.max()) + skin


def _smallest_radius(scene) -> float | None:
    from pdemfem.scene.derived import group_radius_range

    radii = [group_radius_range(group)[0] for group in scene.particles]
    radii += [radius for group in scene.particles for radius in (group.insert.radii or [])]
    return min(radii) if radii else None


def validate_scene_coordinates(scene) -> None:
    """SceneError for a coordinate in the scene file (regions, list positions, walls, domain)
    beyond the float64 resolution limit; run before the insertion, which would bin them."""
    smallest = _smallest_radius(scene)
    if smallest is not None:
        _check_coordinates(scene, np.zeros((0, 3)), smallest, ())


def validate_geometry(scene, inserted, wall_vertices=(), surfaces=(), solids=(), comm=None) -> None:
    """SceneError for coordinates beyond the float64 resolution limit, particles starting outside
    domain.box, a periodic length not above twice the cutoff, or particles starting behind or deep in a
    wall or a solid (validate_start_positions).  `inserted`: the InsertedParticles of the scene;
    `wall_vertices`: (name, vertices) of the mesh walls; `surfaces`, `solids`, `comm`: see
    validate_start_positions (start_surfaces and start_solids build them)."""
    radii = np.asarray(inserted.radii, dtype=float)
    positions = np.asarray(inserted.positions, dtype=float).reshape(-1, 3)
    if len(radii):
        _check_coordinates(scene, positions, float(radii.min()), wall_vertices)
    if scene.domain.box is not None:
        _check_inside_domain(scene, inserted, positions)
        _check_periodic_lengths(scene, radii)
    validate_start_positions(scene, inserted, surfaces, solids, comm)


def start_surfaces(scene, walls, solid_surfaces=()) -> list:
    """(label, vertices, triangles) for validate_start_positions: the triangle-mesh walls among `walls`
    (the built contributor walls) and `solid_surfaces`, (solid name, vertices, triangles) of the solids'
    contact surfaces."""
    found = []
    for wall in walls:
        if hasattr(wall, "triangles") and hasattr(wall, "vertices"):
            index = next((i for i, config in enumerate(scene.walls) if config.name == wall.name), None)
            if index is None:
                continue  # a solid's surface: given in solid_surfaces
            found.append((f"mesh wall '{wall.name}' (walls[{index}].file)", wall.vertices, wall.triangles))
    for name, vertices, triangles in solid_surfaces:
        index = next(i for i, config in enumerate(scene.solids) if config.name == name)
        contact = ", ".join(scene.solids[index].contact)
        found.append((f"the contact surface of solid '{name}' (solids[{index}].contact: {contact})", vertices,
                      triangles))
    return found


def start_solids(scene, solids: dict) -> list:
    """(index, name, points, corner cells of this rank) of the built solids (pdemfem.fem.solid.Solid by name)."""
    found = []
    for index, config in enumerate(scene.solids):
        solid = solids.get(config.name)
        mesh = getattr(solid, "mesh", None)
        if mesh is None:
            continue
        owned = getattr(mesh, "n_owned_cells", len(mesh.cells))
        bounds = getattr(mesh, "bounding_box", None)  # the whole mesh's, the same on every rank
        found.append((index, config.name, mesh.points, np.asarray(mesh.cells)[:owned, :4],
                      mesh.points if bounds is None else bounds))
    return found


def _coordinate_sources(scene, positions, wall_vertices):
    """(key, largest |coordinate|) of everything placed in space."""
    if len(positions):
        yield "particles (inserted positions)", float(np.abs(positions).max())
    for index, group in enumerate(scene.particles):
        insert = group.insert
        if insert.region is not None:
            yield f"particles[{index}].insert.region.box", max(abs(c) for corner in insert.region.box for c in corner)
        if insert.positions:
            yield f"particles[{index}].insert.positions", max(abs(c) for point in insert.positions for c in point)
    for index, wall in enumerate(scene.walls):
        if wall.kind == "plane":
            yield f"walls[{index}].point", max(abs(c) for c in wall.point)
        elif wall.kind == "cylinder" and wall.axis is not None:
            yield f"walls[{index}].axis.point", max(abs(c) for c in wall.axis.point)
        elif wall.kind == "mesh":
            yield f"walls[{index}].center", max(abs(c) for c in wall.center)
    for index, (name, vertices) in enumerate(wall_vertices):
        vertices = np.asarray(vertices, dtype=float)
        if vertices.size:
            key = next((f"walls[{i}].file" for i, wall in enumerate(scene.walls) if wall.name == name), name)
            yield key, float(np.abs(vertices).max())
    if scene.domain.box is not None:
        yield "domain.box", max(abs(c) for corner in scene.domain.box for c in corner)


def _check_coordinates(scene, positions, smallest_radius: float, wall_vertices) -> None:
    limit = COORDINATE_LIMIT_RADII * smallest_radius
    for key, largest in _coordinate_sources(scene, positions, wall_vertices):
        if not np.isfinite(largest) or largest > limit:
            raise SceneError(
                key,
                f"a coordinate of {largest:.3g} m is more than {COORDINATE_LIMIT_RADII:.0e} smallest radii "
                f"({smallest_radius:g} m) from the origin: float64 positions there cannot resolve the contact "
                f"overlaps (resolution {largest * 2.0 ** -52:.2g} m)",
                "move the scene near the origin (or check the units: metres, mesh walls' scale)")


def _check_inside_domain(scene, inserted, positions) -> None:
    lower, upper = (np.asarray(corner, dtype=float) for corner in scene.domain.box)
    bounded = np.array(["xyz"[axis] not in scene.domain.periodic for axis in range(3)])
    if not len(positions) or not bounded.any():
        return
    outside = np.any(((positions < lower) | (positions > upper)) & bounded, axis=1)
    if not outside.any():
        return
    groups = np.asarray(inserted.group_index)
    index = int(groups[np.flatnonzero(outside)[0]])
    group = scene.particles[index]
    count = int(np.count_nonzero(outside & (groups == index)))
    total = int(np.count_nonzero(groups == index))
    place = "insert.region.box" if group.insert.kind != "list" else "insert.positions"
    raise SceneError(
        f"particles[{index}].{place}",
        f"{count} of the {total} particles of group '{group.name}' start outside domain.box "
        f"{[list(lower), list(upper)]}: the run would remove them as lost at step 0",
        "move the insertion inside domain.box, or enlarge domain.box")


def _check_periodic_lengths(scene, radii) -> None:
    cutoff = interaction_cutoff(scene, radii)
    lower, upper = scene.domain.box
    for axis_name in scene.domain.periodic:
        axis = "xyz".index(axis_name)
        length = upper[axis] - lower[axis]
        if length <= 2.0 * cutoff:
            raise SceneError(
                f"domain.box ({axis_name}, periodic)",
                f"the periodic length {length:g} m is not larger than twice the interaction cutoff {cutoff:g} m "
                f"(largest diameter + skin): a particle would touch its own periodic image",
                "enlarge the periodic domain or reduce neighbors.skin")


# --------------------------------------------------------------------------- starting overlaps

# A particle may start touching a wall or a solid's surface (a settled packing rests on its floor with
# overlaps of 1e-3..1e-2 radii), but not deeper than this fraction of its radius: the contact would shoot it
# out with the energy of the whole overlap at step 0, and a centre behind a plane or inside a solid is
# pushed the wrong way or not at all.
START_OVERLAP_TOLERANCE = 0.05


def validate_start_positions(scene, inserted, surfaces=(), solids=(), comm=None) -> None:
    """SceneError for particles that start behind or deep in a plane wall, deep in a mesh wall or a solid's
    contact surface, or with their centre inside a solid's volume (`pdemfem check` and `run`, before any
    output exists).

    `surfaces`: (label, vertices, triangles) of the mesh walls and the solids' contact surfaces (whole on
    every rank); `solids`: (index, name, points, corner cells, bounding points) of each solid's cells, the
    cells of this rank (the run's solids are distributed: the inside flags are combined over `comm`)."""
    radii = np.asarray(inserted.radii, dtype=float)
    positions = np.ascontiguousarray(np.asarray(inserted.positions, dtype=float).reshape(-1, 3))
    if not len(radii):
        return
    groups = np.asarray(inserted.group_index)
    _check_planes(scene, groups, positions, radii)
    for index, name, points, cells, bounds in solids:
        inside = _inside_cells(positions, points, cells)
        if comm is not None and comm.size > 1:
            from mpi4py import MPI

            flags = inside.astype(np.int8)
            comm.Allreduce(MPI.IN_PLACE, flags, op=MPI.MAX)
            inside = flags.astype(bool)
        if inside.any():
            first = int(np.flatnonzero(inside)[0])
            group = int(groups[first])
            rows = inside & (groups == group)
            raise SceneError(
                _insert_key(scene, group),
                f"{_count_text(scene, groups, rows, group)} start with their centre inside solid '{name}' "
                f"(solids[{index}].mesh; e.g. the particle at {_point_text(positions[first])}): a particle "
                f"inside a solid is never pushed out (the solid's contact surfaces have no thickness)",
                f"move the insertion (region or positions) out of solid '{name}' (its mesh's bounding box is "
                f"{_box_text(bounds)}), or move the solid")

    for label, vertices, triangles in surfaces:
        distance = _surface_distances(positions, radii, vertices, triangles)
        deep = distance < (1.0 - START_OVERLAP_TOLERANCE) * radii
        if deep.any():
            first = int(np.flatnonzero(deep)[0])
            index = int(groups[first])
            rows = deep & (groups == index)
            deepest = float(np.max((radii - distance)[rows] / radii[rows]))
            raise SceneError(
                _insert_key(scene, index),
                f"{_count_text(scene, groups, rows, index)} start overlapping {label} by more than "
                f"{START_OVERLAP_TOLERANCE:g} of their radius (the deepest by {deepest:.3g} radii; a particle "
                f"at {_point_text(positions[first])}): the surface would shoot them out with the energy of the "
                f"whole overlap at step 0",
                "move the insertion (region or positions) away from the surface, at least one radius from it, "
                "or move the surface")


def _insert_key(scene, index: int) -> str:
    group = scene.particles[index]
    return f"particles[{index}].insert." + ("positions" if group.insert.kind == "list" else "region.box")


def _count_text(scene, groups, rows, index: int) -> str:
    count = int(np.count_nonzero(rows))
    total = int(np.count_nonzero(groups == index))
    return f"{count} of the {total} particles of group '{scene.particles[index].name}'"


def _point_text(point) -> str:
    return "[" + ", ".join(f"{float(c):.4g}" for c in point) + "]"


def _box_text(points) -> str:
    points = np.asarray(points, dtype=float).reshape(-1, 3)
    if not len(points):
        return "empty"
    return f"[{_point_text(points.min(axis=0))}, {_point_text(points.max(axis=0))}]"


def _check_planes(scene, groups, positions, radii) -> None:
    for wall_index, wall in enumerate(scene.walls):
        if wall.kind != "plane":
            continue
        normal = np.asarray(wall.normal, dtype=float)
        normal = normal / np.linalg.norm(normal)
        distance = (positions - np.asarray(wall.point, dtype=float)) @ normal
        deep = distance < (1.0 - START_OVERLAP_TOLERANCE) * radii
        if not deep.any():
            continue
        first = int(np.flatnonzero(deep)[0])
        index = int(groups[first])
        rows = deep & (groups == index)
        behind = int(np.count_nonzero(rows & (distance < 0.0)))
        worst = float(distance[rows].min())
        where = (f"{behind} with their centre behind the plane, the deepest {-worst:.3g} m behind it"
                 if behind else f"the deepest overlapping it by {(1.0 - worst / radii[rows][np.argmin(distance[rows])]):.3g} radii")
        raise SceneError(
            _insert_key(scene, index),
            f"{_count_text(scene, groups, rows, index)} start behind plane wall '{wall.name}' (walls[{wall_index}]: "
            f"point {_point_text(wall.point)}, normal {_point_text(wall.normal)}, which points to the side the "
            f"particles belong on) or overlap it by more than {START_OVERLAP_TOLERANCE:g} of their radius "
            f"({where}): the wall would push them through the plane or shoot them out at step 0",
            f"put the particles on the side walls[{wall_index}].normal points to, at least one radius from the "
            f"plane: move the insertion (region or positions), or move walls[{wall_index}].point / flip its normal")


def _surface_distances(positions, radii, vertices, triangles) -> np.ndarray:
    """Distance from each centre to the nearest triangle, where it is below its radius (else the radius)."""
    from pdemfem.walls.bvh import BVH

    vertices = np.ascontiguousarray(vertices, dtype=np.float64).reshape(-1, 3)
    triangles = np.ascontiguousarray(triangles, dtype=np.int32).reshape(-1, 3)
    distance = radii.copy()
    if not len(triangles):
        return distance
    offsets, items = BVH(vertices, triangles).query(vertices, positions, radii)
    return _nearest(positions, vertices, triangles, offsets, items, distance)


def _nearest(positions, vertices, triangles, offsets, items, distance):
    from pdemfem.scene.start_geometry import nearest_triangle_distance

    return nearest_triangle_distance(positions, vertices, triangles, offsets, items, distance)


def _inside_cells(positions, points, cells) -> np.ndarray:
    """True for each centre inside (or on) one of the tetrahedra `cells` (corner indices into `points`)."""
    from pdemfem.scene.start_geometry import grid_cells_of, points_in_tetrahedra

    points = np.ascontiguousarray(points, dtype=np.float64).reshape(-1, 3)
    cells = np.ascontiguousarray(np.asarray(cells)[:, :4], dtype=np.int64)
    inside = np.zeros(len(positions), dtype=np.bool_)
    if not len(cells) or not len(positions):
        return inside
    low = points[cells.ravel()].min(axis=0)
    high = points[cells.ravel()].max(axis=0)
    candidates = np.flatnonzero(np.all((positions >= low) & (positions <= high), axis=1))
    if not len(candidates):
        return inside
    near = np.ascontiguousarray(positions[candidates])
    origin, size, dims, order, starts = grid_cells_of(near)
    found = np.zeros(len(near), dtype=np.bool_)
    points_in_tetrahedra(near, points, cells, origin, size, dims, order, starts, found)
    inside[candidates] = found
    return inside


# --------------------------------------------------------------------------- solids' group names

_GROUP_WHERE = re.compile(r"group '([^']*)'$")
_FILE_GROUPS = re.compile(r"groups: (\[[^\]]*\])")


def solid_group_keys(config) -> list:
    """(key below solids[i], group name, regions allowed) of every group a solid's config names."""
    keys = [(f"fixed[{i}]", group, True) for i, group in enumerate(config.fixed)]
    keys += [(f"prescribed[{i}].group", entry.group, True) for i, entry in enumerate(config.prescribed)]
    keys += [(f"tractions[{i}].group", entry.group, False) for i, entry in enumerate(config.tractions)]
    keys += [(f"contact[{i}]", group, False) for i, group in enumerate(config.contact)]
    if config.thermal is not None:
        keys += [(f"thermal.{kind}[{i}].group", group, False) for kind, i, group in config.thermal.groups()]
    return keys


def box_mesh_group_problems(scene) -> list:
    """(key path, problem, fix) for each group a solid with a generated box mesh names that is neither a
    box face (xmin..zmax) nor, where allowed, one of its regions: a box has no other groups."""
    from pdemfem.fem.config import BOX_FACES, BoxMeshConfig

    found = []
    for index, config in enumerate(scene.solids):
        if not isinstance(config.mesh, BoxMeshConfig):
            continue
        for key, group, regions_allowed in solid_group_keys(config):
            names = list(BOX_FACES) + (list(config.regions) if regions_allowed else [])
            if group in names:
                continue
            found.append((f"solids[{index}].{key}", *_unknown_group_text(group, names, "box", config, index,
                                                                        regions_allowed)))
    return found


def _unknown_group_text(group, names, kind, config, index, regions_allowed) -> tuple:
    import difflib

    close = difflib.get_close_matches(group, names, n=1, cutoff=0.6)
    regions = f"; regions: {', '.join(config.regions)}" if regions_allowed and config.regions else ""
    if kind == "box":
        problem = (f"the generated box mesh (solids[{index}].mesh.box) has no group '{group}': its groups are its "
                   f"faces {', '.join(names[:6])}{regions}")
        other = (f"use one of its faces, or define a region under solids[{index}].regions" if regions_allowed
                 else "use one of its faces")
    else:
        problem = f"the mesh file {kind} has no group '{group}' (its groups: {', '.join(names) or 'none'}{regions})"
        other = "correct the name, or add a 2-D physical group with this name to the mesh (gmsh)"
    fix = f"did you mean '{close[0]}'? ({other})" if close else other
    return problem, fix


@contextmanager
def solid_errors_named(scene):
    """Building the scene's solids within: a misnamed mesh group is raised as the SceneError that names its scene key
    (solids[i].fixed[k], ...) with a "did you mean" (locate_solid_error); other errors pass unchanged."""
    try:
        yield
    except (MeshError, SceneError) as error:
        located = locate_solid_error(scene, error)
        if located is error:
            raise
        raise located from None


def locate_solid_error(scene, error):
    """A mesh group error raised while building the solids (pdemfem.fem names only the mesh and the
    group) as a SceneError naming the scene key that names the group, with a "did you mean"; other
    errors are returned unchanged."""
    from pdemfem.fem.config import BOX_FACES, BoxMeshConfig

    problem = getattr(error, "problem", "")
    match = _GROUP_WHERE.search(getattr(error, "where", "") or "")
    if match is None:
        match = re.search(r"group '([^']*)': the mesh has no such group", problem)
    if match is None:
        return error
    group = match.group(1)
    for index, config in enumerate(scene.solids):
        for key, name, regions_allowed in solid_group_keys(config):
            if name != group:
                continue
            if "no such group" in problem:
                listed = _FILE_GROUPS.search(problem)
                try:
                    import ast

                    file_groups = list(ast.literal_eval(listed.group(1))) if listed else []
                except (ValueError, SyntaxError):
                    file_groups = []
                names = [str(g) for g in file_groups] + list(BOX_FACES)
                names += list(config.regions) if regions_allowed else []
                kind = "box" if isinstance(config.mesh, BoxMeshConfig) else str(config.mesh)
                text, fix = _unknown_group_text(group, names, kind, config, index, regions_allowed)
                if kind != "box":
                    text = (f"the mesh file {config.mesh} has no group '{group}' (its physical groups: "
                            f"{', '.join(map(str, file_groups)) or 'none'}; box faces of its bounding box: "
                            f"{', '.join(BOX_FACES)})")
            else:
                text, fix = f"group '{group}' of {getattr(error, 'where', '')}: {problem}", error.fix
            located = SceneError(f"solids[{index}].{key}", text, fix)
            located.exit_code = getattr(error, "exit_code", 2)
            return located
    return error

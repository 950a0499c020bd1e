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

import numpy as np

from pdemfem.errors import SceneError

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


def validate_geometry(scene, inserted, wall_vertices=()) -> None:
    """SceneError for coordinates beyond the float64 resolution limit, particles starting outside
    domain.box, or a periodic length not above twice the cutoff.  `inserted`: the
    InsertedParticles of the scene; `wall_vertices`: (name, vertices) of the mesh walls."""
    radii = np.asarray(inserted.radii, dtype=float)
    positions = np.asarray(inserted.positions, dtype=float).reshape(-1, 3)
    if len(radii):
        _check_coordinates(scene, positions, float(radii.min()), wall_vertices)
    if scene.domain.box is not None:
        _check_inside_domain(scene, inserted, positions)
        _check_periodic_lengths(scene, radii)


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

"""Mesh and cylinder walls from the scene's wall entries (plain config objects, no scene import).

    walls = build_contributor_walls(scene.walls, material_names, resolve_file=lambda p: base / p)

Plane walls are not built here: they are one PlaneWalls array object (pdemfem.walls.plane).
"""
from __future__ import annotations

from pdemfem.errors import MeshError, SceneError
from pdemfem.walls.cylinder import CylinderWall
from pdemfem.walls.mesh import MeshWall
from pdemfem.walls.readers import read_surface


def build_contributor_walls(wall_configs, material_names, resolve_file, skin=None) -> list:
    """MeshWall / CylinderWall objects for the mesh and cylinder entries of `wall_configs`, in order.

    resolve_file: a mesh wall's `file` as written in the scene -> the path to read."""
    walls = []
    for index, wall in enumerate(wall_configs):
        material = list(material_names).index(wall.material)
        if wall.kind == "mesh":
            path = resolve_file(wall.file)
            try:
                vertices, triangles = read_surface(path, wall.scale)
            except MeshError as error:
                raise SceneError(f"walls[{index}].file", f"{path}: {error.problem}", error.fix) from None
            walls.append(MeshWall(wall.name, vertices, triangles, material, velocity=wall.velocity,
                                  angular_velocity=wall.angular_velocity, center=wall.center,
                                  smooth_angle=wall.smooth_angle, one_sided=wall.one_sided, skin=skin,
                                  transport_velocity=wall.transport_velocity))
        elif wall.kind == "cylinder":
            walls.append(CylinderWall(wall.name, wall.axis.point, wall.axis.direction, wall.radius, wall.inside,
                                      material, velocity=wall.velocity, angular_velocity=wall.angular_velocity))
        else:
            continue
        if wall.temperature is not None:
            walls[-1].set_temperature(wall.temperature)
    return walls

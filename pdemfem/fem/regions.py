"""Node groups chosen by a region of space (`solids[].regions`): a box or an infinite cylinder.

A region names the mesh nodes inside it; the name can then stand wherever a node group is
accepted (`fixed`, `prescribed`), e.g. the line of nodes under a belt resting on an idler.
Surface loads and contact need faces, so a region is refused there (SolidConfig).

Tolerance: a node counts as inside when it lies within REGION_TOLERANCE x the mesh's shortest
edge of the region (box faces and cylinder mantle grown by that much), so a region drawn exactly
on a row of nodes takes them despite round-off in the mesh coordinates, while no node of the
neighbouring row (at least one shortest edge away; half of it for P2 midside nodes) can be taken
by the tolerance alone.
"""
from __future__ import annotations

import numpy as np

from pdemfem.errors import SceneError

REGION_TOLERANCE = 1e-3  # of the shortest edge: far above coordinate round-off, far below any node spacing


def shortest_edge(points: np.ndarray, tets: np.ndarray) -> float:
    """Length of the shortest edge of the tetrahedra (corner nodes)."""
    shortest = np.inf
    for i in range(4):
        for j in range(i + 1, 4):
            shortest = min(shortest, float(np.min(np.linalg.norm(points[tets[:, i]] - points[tets[:, j]], axis=1))))
    return shortest


def nodes_inside(points: np.ndarray, region, tolerance: float) -> np.ndarray:
    """Indices of the points inside `region` (a RegionConfig) grown by `tolerance` [m]."""
    if region.box is not None:
        low, high = np.asarray(region.box[0], float), np.asarray(region.box[1], float)
        inside = np.all((points >= low - tolerance) & (points <= high + tolerance), axis=1)
    else:
        cylinder = region.cylinder
        axis = np.asarray(cylinder.direction, float)
        axis = axis / np.linalg.norm(axis)
        offset = points - np.asarray(cylinder.point, float)
        across = offset - np.outer(offset @ axis, axis)
        inside = np.linalg.norm(across, axis=1) <= cylinder.radius + tolerance
    return np.flatnonzero(inside)


def region_node_groups(points: np.ndarray, tets: np.ndarray, regions: dict, key_prefix: str,
                       file_groups=()) -> dict:
    """name -> node indices (into points) of every region; SceneError for an empty region or a region
    named like one of the mesh's own groups.  points may hold P2 midside nodes after the corners."""
    groups = {}
    if not regions:
        return groups
    tolerance = REGION_TOLERANCE * shortest_edge(points, tets)
    for name, region in regions.items():
        if name in file_groups:
            raise SceneError(f"{key_prefix}.regions.{name}",
                             "the mesh has a physical group of the same name",
                             "rename the region so that a group name means one thing")
        nodes = nodes_inside(points, region, tolerance)
        if len(nodes) == 0:
            raise SceneError(f"{key_prefix}.regions.{name}",
                             f"no mesh node lies in the region (tolerance {tolerance:.3g} m; mesh bounding box "
                             f"{points.min(axis=0).tolist()} .. {points.max(axis=0).tolist()})",
                             "move or enlarge the region so that it contains the nodes to hold")
        groups[name] = nodes
    return groups

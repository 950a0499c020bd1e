"""Initial placement of clump groups: list, lattice and random, with given or random orientations.

Called by pdemfem.particles.insert for a group with `clump:`.  Positions are the clumps' centres of
mass; an orientation turns the clump's own frame into the world's.  Random orientations are
uniform on the rotations (a unit quaternion from four independent normal numbers, normalised),
drawn from the group's seed, so every rank draws the same clumps whatever the rank count.  No
member of a new clump may overlap a particle or member placed before it (members of one clump
may overlap each other: that is the shape).

The returned `ClumpGroup` holds the bodies (centre, orientation body principal frame -> world,
velocity, angular velocity in the world frame) and their member spheres in world coordinates,
members of one body consecutive, bodies in placement order.
"""
from __future__ import annotations

from dataclasses import dataclass

import numpy as np
from numba import njit

from pdemfem.clumps.quaternion import quaternion_products, rotation_matrices, rotation_matrix
from pdemfem.clumps.template import clump_template
from pdemfem.errors import SceneError
from pdemfem.particles.placement_grid import overlaps_stored, store_sphere

# |q| may differ from 1 by this much in a scene (four digits typed by hand); it is then normalised.
UNIT_TOLERANCE = 1e-3


@dataclass
class ClumpGroup:
    positions: np.ndarray            # (B, 3) centres of mass
    orientations: np.ndarray         # (B, 4) body principal frame -> world
    velocities: np.ndarray           # (B, 3)
    angular_velocities: np.ndarray   # (B, 3) world frame
    member_positions: np.ndarray     # (B n, 3)
    member_radii: np.ndarray         # (B n,)
    member_velocities: np.ndarray    # (B n, 3)
    member_angular_velocities: np.ndarray
    member_body: np.ndarray          # (B n,) body index within the group
    member_offsets: np.ndarray       # (B n, 3) body principal frame
    template: object                 # pdemfem.clumps.template.ClumpTemplate


def random_orientations(rng, count: int) -> np.ndarray:
    """(count, 4) unit quaternions uniform on the rotations (normalised 4-D normal vectors)."""
    q = rng.standard_normal((count, 4))
    return q / np.linalg.norm(q, axis=1)[:, None]


def unit_quaternions(values, where: str) -> np.ndarray:
    q = np.asarray(values, dtype=np.float64).reshape(-1, 4)
    norms = np.linalg.norm(q, axis=1)
    bad = np.flatnonzero(~(np.abs(norms - 1.0) <= UNIT_TOLERANCE))
    if len(bad):
        raise SceneError(f"{where}[{int(bad[0])}]" if q.shape[0] > 1 or where.endswith("orientations") else where,
                         f"{q[bad[0]].tolist()} is not a unit quaternion (norm {norms[bad[0]]:.6g})",
                         "give [w, x, y, z] with w^2 + x^2 + y^2 + z^2 = 1, e.g. [cos(a/2), sin(a/2) n] for a "
                         "turn by a about the unit axis n; [1, 0, 0, 0] keeps the clump as given")
    return q / norms[:, None]


def members_of(template, positions, orientations, velocities, angular_velocities, first_body: int = 0):
    """Member spheres (world frame) of bodies at `positions` with body orientations `orientations`."""
    count = len(positions)
    n = len(template.member_radii)
    levers = np.einsum("bij,mj->bmi", rotation_matrices(orientations), template.member_offsets)  # (B, n, 3)
    member_positions = (positions[:, None, :] + levers).reshape(-1, 3)
    member_velocities = (velocities[:, None, :] + np.cross(angular_velocities[:, None, :], levers)).reshape(-1, 3)
    member_spins = np.repeat(angular_velocities, n, axis=0)
    member_body = np.repeat(np.arange(first_body, first_body + count, dtype=np.int64), n)
    return (member_positions, np.tile(template.member_radii, count), member_velocities, member_spins, member_body,
            np.tile(template.member_offsets, (count, 1)))


def place_clump_group(scene, index: int, group, rng, placed_positions, placed_radii, lattice_positions):
    """ClumpGroup of scene.particles[index] (`lattice_positions(group, where, rng, largest)`: the sphere lattice)."""
    where = f"particles[{index}]"
    insert = group.insert
    density = scene.materials[group.material].density
    template = clump_template(group.clump, density, where=f"{where}.clump")
    principal = template.principal_orientation
    if insert.kind == "list":
        positions = np.array(insert.positions, dtype=float).reshape(-1, 3)
        count = len(positions)
        given = (unit_quaternions(insert.orientations, f"{where}.insert.orientations")
                 if insert.orientations is not None else np.tile([1.0, 0.0, 0.0, 0.0], (count, 1)))
        orientations = quaternion_products(given, np.tile(principal, (count, 1)))
        velocities = (np.array(insert.velocities, dtype=float).reshape(-1, 3) if insert.velocities is not None
                      else np.tile(np.array(insert.velocity, dtype=float), (count, 1)))
        spins = (np.array(insert.angular_velocities, dtype=float).reshape(-1, 3)
                 if insert.angular_velocities is not None else np.zeros((count, 3)))
    else:
        count = insert.count
        velocities = np.tile(np.array(insert.velocity, dtype=float), (count, 1))
        spins = np.zeros((count, 3))
        if insert.kind == "lattice":
            positions = lattice_positions(group, f"{where}.insert", rng, template.extent)
            given = (np.tile(unit_quaternions(insert.orientation, f"{where}.insert.orientation"), (count, 1))
                     if insert.orientation is not None else random_orientations(rng, count))
            orientations = quaternion_products(given, np.tile(principal, (count, 1)))
        else:
            positions, orientations = _random_clumps(group, where, template, placed_positions, placed_radii)
    return ClumpGroup(positions, orientations, velocities, spins,
                      *members_of(template, positions, orientations, velocities, spins), template)


def _random_clumps(group, where, template, placed_positions, placed_radii):
    insert = group.insert
    low, high = (np.array(corner, dtype=float) for corner in insert.region.box)
    extent = template.extent
    if np.any(high - low < 2.0 * extent):
        raise SceneError(f"{where}.insert.region.box",
                         f"the region is thinner than one clump (bounding diameter {2 * extent:g} m)",
                         "enlarge region.box")
    use_given = insert.orientation is not None
    given = (quaternion_products(unit_quaternions(insert.orientation, f"{where}.insert.orientation"),
                                 template.principal_orientation)[0] if use_given else np.array([1.0, 0, 0, 0]))
    largest = float(max(template.member_radii.max(), placed_radii.max() if len(placed_radii) else 0.0))
    grid_lower = np.minimum(low, placed_positions.min(axis=0) if len(placed_positions) else low)
    grid_upper = np.maximum(high, placed_positions.max(axis=0) if len(placed_positions) else high)
    cell_size = 2.0 * largest
    dimensions = np.floor((grid_upper - grid_lower) / cell_size).astype(np.int64) + 1
    centres, orientations, placed = _random_place_clumps(
        low + extent, high - extent, int(insert.count), np.ascontiguousarray(template.member_offsets),
        np.ascontiguousarray(template.member_radii), given, use_given,
        np.ascontiguousarray(placed_positions, dtype=float).reshape(-1, 3),
        np.ascontiguousarray(placed_radii, dtype=float),
        cell_size, dimensions, grid_lower, insert.max_attempts, insert.seed)
    if placed < insert.count:
        raise SceneError(f"{where}.insert.count",
                         f"random insertion placed only {placed} of {insert.count} clumps",
                         "enlarge region.box, reduce count, raise max_attempts, or use kind: lattice")
    return centres, orientations


@njit(cache=True)
def _random_place_clumps(lower, upper, count, offsets, radii, given, use_given, fixed_positions, fixed_radii,
                         cell_size, dimensions, grid_lower, max_attempts, seed):
    """Random sequential addition of clumps (centre in [lower, upper], random or given orientation)
    against the fixed spheres and the clumps placed so far, on a linked-cell grid of member spheres.
    Returns (centres, body orientations, placed count)."""
    np.random.seed(seed)
    nx, ny, nz = dimensions[0], dimensions[1], dimensions[2]
    members = radii.shape[0]
    total = fixed_positions.shape[0] + count * members
    all_positions = np.empty((total, 3))
    all_radii = np.empty(total)
    cell_head = -np.ones(nx * ny * nz, dtype=np.int64)
    next_in_cell = -np.ones(total, dtype=np.int64)
    stored = 0
    for k in range(fixed_positions.shape[0]):
        stored = store_sphere(fixed_positions[k], fixed_radii[k], stored, all_positions, all_radii, cell_head,
                              next_in_cell, grid_lower, cell_size, dimensions)
    centres = np.empty((count, 3))
    orientations = np.empty((count, 4))
    rotation = np.empty((3, 3))
    candidate_members = np.empty((members, 3))
    q = np.empty(4)
    for p in range(count):
        success = False
        for attempt in range(max_attempts):
            centre = np.empty(3)
            for axis in range(3):
                centre[axis] = lower[axis] + (upper[axis] - lower[axis]) * np.random.random()
            if use_given:
                for k in range(4):
                    q[k] = given[k]
            else:
                norm = 0.0
                for k in range(4):
                    q[k] = np.random.normal(0.0, 1.0)
                    norm += q[k] * q[k]
                norm = np.sqrt(norm)
                for k in range(4):
                    q[k] /= norm
            rotation_matrix(q[0], q[1], q[2], q[3], rotation)
            free = True
            for m in range(members):
                for axis in range(3):
                    candidate_members[m, axis] = (centre[axis] + rotation[axis, 0] * offsets[m, 0]
                                                  + rotation[axis, 1] * offsets[m, 1]
                                                  + rotation[axis, 2] * offsets[m, 2])
                if overlaps_stored(candidate_members[m], radii[m], all_positions, all_radii, cell_head, next_in_cell,
                                   grid_lower, cell_size, dimensions):
                    free = False
                    break
            if free:
                for axis in range(3):
                    centres[p, axis] = centre[axis]
                for k in range(4):
                    orientations[p, k] = q[k]
                for m in range(members):
                    stored = store_sphere(candidate_members[m], radii[m], stored, all_positions, all_radii, cell_head,
                                          next_in_cell, grid_lower, cell_size, dimensions)
                success = True
                break
        if not success:
            return centres, orientations, p
    return centres, orientations, count

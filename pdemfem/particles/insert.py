"""Initial particle placement: explicit lists, lattices and random packings.

Groups are inserted in scene order and each new particle is checked against all
earlier ones, so no insertion starts with overlaps.  Ids are 0..N-1 in that
order.  Failures are SceneErrors naming the key and the fix.

A clump group (pdemfem.clumps.insert) inserts its clumps' member spheres, each clump's
members consecutively; `member_body` names each sphere's clump (-1: a single sphere) and
`clumps` holds the bodies.  Members of one clump may overlap each other, nothing else.
"""
from __future__ import annotations

from dataclasses import dataclass

import numpy as np
from numba import njit

from pdemfem.clumps.insert import place_clump_group
from pdemfem.errors import SceneError
from pdemfem.neighbors.cells import cell_grid, cell_indices, cell_starts
from pdemfem.particles.periodic_images import PeriodicBox
from pdemfem.particles.placement_grid import overlaps_stored, store_sphere
from pdemfem.scene.derived import group_radius_range
from pdemfem.scene.inputs import START_OVERLAP_TOLERANCE


@dataclass
class InsertedParticles:
    group_index: np.ndarray
    radii: np.ndarray
    positions: np.ndarray
    velocities: np.ndarray
    angular_velocities: np.ndarray
    # Clumps: each sphere's body (index into `clumps`' arrays; -1 for a single sphere), its offset from
    # the body's centre of mass (body principal frame), and the bodies (None without clump groups).
    member_body: np.ndarray = None
    member_offsets: np.ndarray = None
    clumps: "InsertedClumps" = None


@dataclass
class InsertedClumps:
    group_index: np.ndarray          # (B,) scene group of each body
    positions: np.ndarray            # (B, 3) centres of mass
    orientations: np.ndarray         # (B, 4) body principal frame -> world
    velocities: np.ndarray
    angular_velocities: np.ndarray   # (B, 3) world frame
    templates: dict                  # group index -> pdemfem.clumps.template.ClumpTemplate


# Overlaps smaller than this fraction of the smaller radius count as touching, not overlapping.
OVERLAP_TOLERANCE = 1e-9


@njit(cache=True)
def _first_overlap(positions, radii, labels, cells, starts, dimensions, tolerance):
    nx, ny, nz = dimensions[0], dimensions[1], dimensions[2]
    for i in range(positions.shape[0]):
        cell = cells[i]
        cx = cell % nx
        cy = (cell // nx) % ny
        cz = cell // (nx * ny)
        for dz in range(-1, 2):
            for dy in range(-1, 2):
                for dx in range(-1, 2):
                    x, y, z = cx + dx, cy + dy, cz + dz
                    if x < 0 or y < 0 or z < 0 or x >= nx or y >= ny or z >= nz:
                        continue
                    neighbour = x + nx * (y + ny * z)
                    for j in range(starts[neighbour], starts[neighbour + 1]):
                        if j <= i or (labels[i] >= 0 and labels[i] == labels[j]):
                            continue  # members of one clump may overlap
                        distance = 0.0
                        for axis in range(3):
                            offset = positions[i, axis] - positions[j, axis]
                            distance += offset * offset
                        limit = radii[i] + radii[j] - tolerance * min(radii[i], radii[j])
                        if distance < limit * limit:
                            return i, j
    return -1, -1


def first_overlap(positions: np.ndarray, radii: np.ndarray, labels=None, tolerance: float = OVERLAP_TOLERANCE,
                  periodic_box=None):
    """Indices (i, j) of some pair overlapping by more than `tolerance` of the smaller radius, or None.
    `labels`: clump of each sphere (-1: none); members of one clump are not a pair.  `periodic_box`
    (periodic_images.PeriodicBox): on its periodic axes the pairs are also tested through the faces."""
    if len(radii) < 2:
        return None
    labels = np.full(len(radii), -1, dtype=np.int64) if labels is None else np.asarray(labels, dtype=np.int64)
    if periodic_box is not None:
        positions, radii, rows = periodic_box.with_images(positions, radii, 2.0 * float(radii.max()))
        overlap = first_overlap(positions, radii, labels[rows], tolerance)
        return None if overlap is None else (int(rows[overlap[0]]), int(rows[overlap[1]]))
    lower, size, dimensions = cell_grid(positions, 2.0 * float(radii.max()))
    cells = cell_indices(positions, lower, size, dimensions)
    order = np.argsort(cells, kind="stable")
    sorted_cells = np.ascontiguousarray(cells[order])
    starts = cell_starts(sorted_cells, int(np.prod(dimensions)))
    i, j = _first_overlap(np.ascontiguousarray(positions[order]), np.ascontiguousarray(radii[order]),
                          np.ascontiguousarray(labels[order]), sorted_cells, starts, dimensions, tolerance)
    if i < 0:
        return None
    return int(order[i]), int(order[j])


@njit(cache=True)
def _random_place(lower, upper, radii, fixed_positions, fixed_radii, cell_size, dimensions, grid_lower,
                  max_attempts, seed):
    """Random sequential addition with a linked-cell grid; returns (positions, placed count)."""
    np.random.seed(seed)
    nx, ny, nz = dimensions[0], dimensions[1], dimensions[2]
    total = fixed_positions.shape[0] + radii.shape[0]
    all_positions = np.empty((total, 3))
    all_radii = np.empty(total)
    cell_head = -np.ones(nx * ny * nz, dtype=np.int64)
    next_in_cell = -np.ones(total, dtype=np.int64)
    stored = 0
    for k in range(fixed_positions.shape[0]):
        stored = store_sphere(fixed_positions[k], fixed_radii[k], stored, all_positions, all_radii, cell_head,
                              next_in_cell, grid_lower, cell_size, dimensions)
    placed = 0
    positions = np.empty((radii.shape[0], 3))
    for p in range(radii.shape[0]):
        radius = radii[p]
        success = False
        for attempt in range(max_attempts):
            candidate = np.empty(3)
            for axis in range(3):
                low = lower[axis] + radius
                high = upper[axis] - radius
                candidate[axis] = low + (high - low) * np.random.random()
            if not overlaps_stored(candidate, radius, all_positions, all_radii, cell_head, next_in_cell, grid_lower,
                                   cell_size, dimensions):
                positions[p] = candidate
                stored = store_sphere(candidate, radius, stored, all_positions, all_radii, cell_head, next_in_cell,
                                      grid_lower, cell_size, dimensions)
                placed += 1
                success = True
                break
        if not success:
            return positions, placed
    return positions, placed


def _group_radii(group, count, rng):
    if isinstance(group.radius, float):
        return np.full(count, group.radius)
    return rng.uniform(group.radius.min, group.radius.max, size=count)


def _largest_radius(group) -> float:
    return group.radius if isinstance(group.radius, float) else group.radius.max


def _lattice_positions(group, where: str, rng, largest=None):
    """Sites of a simple cubic lattice for particles of bounding radius `largest` (default: the group's)."""
    insert = group.insert
    low, high = (np.array(corner, dtype=float) for corner in insert.region.box)
    largest = _largest_radius(group) if largest is None else float(largest)
    spacing = insert.spacing or 2.0 * largest * 1.05
    if spacing < 2.0 * largest:
        raise SceneError(f"{where}.spacing", f"spacing {spacing} is smaller than the largest diameter {2 * largest}",
                         "use a spacing of at least the largest particle diameter, or leave it out")
    # Jitter moves a site by up to half of `jitter * gap` each way: keep that margin inside the box.
    margin = 0.5 * insert.jitter * (spacing - 2.0 * largest)
    per_axis = np.floor((high - low - 2.0 * largest - 2.0 * margin) / spacing).astype(int) + 1
    per_axis = np.maximum(per_axis, 0)
    capacity = int(np.prod(per_axis))
    if capacity < insert.count:
        raise SceneError(f"{where}.count",
                         f"the region holds only {capacity} particles on a lattice of spacing {spacing:g} m "
                         f"({per_axis[0]} x {per_axis[1]} x {per_axis[2]}), not {insert.count}",
                         "enlarge region.box, reduce count, or reduce spacing")
    index = np.arange(insert.count)
    ix = index % per_axis[0]
    iy = (index // per_axis[0]) % per_axis[1]
    iz = index // (per_axis[0] * per_axis[1])
    positions = low + largest + margin + spacing * np.stack([ix, iy, iz], axis=1).astype(float)
    if insert.jitter > 0.0:
        gap = spacing - 2.0 * largest
        positions += rng.uniform(-0.5, 0.5, size=positions.shape) * insert.jitter * gap
    return positions


def insert_particles(scene) -> InsertedParticles:
    """Place every group's particles; raise SceneError when a group cannot be placed."""
    group_index, radii, positions, velocities, spins = [], [], [], [], []
    member_body, member_offsets = [], []
    bodies = {"group_index": [], "positions": [], "orientations": [], "velocities": [], "angular_velocities": []}
    templates = {}
    body_count = 0
    placed_positions = np.zeros((0, 3))
    placed_radii = np.zeros(0)
    placed_labels = np.zeros(0, dtype=np.int64)
    periodic_box = PeriodicBox.from_scene(scene)
    largest = max((group_radius_range(group)[1] for group in scene.particles), default=0.0)
    if periodic_box is not None and np.any(periodic_box.periodic & (periodic_box.upper - periodic_box.lower
                                                                    <= 4.0 * largest)):
        # A period of two diameters or less would have the particles overlap their own images: the particle
        # system refuses it, naming the period and the interaction cutoff it must exceed twice.
        periodic_box = None
    for index, group in enumerate(scene.particles):
        where = f"particles[{index}].insert"
        insert = group.insert
        if insert.kind == "stream":  # inserted over time (pdemfem.particles.stream)
            continue
        rng = np.random.default_rng(insert.seed)
        group_labels = None
        if group.clump is not None:
            clumps = place_clump_group(scene, index, group, rng, placed_positions, placed_radii, _lattice_positions)
            templates[index] = clumps.template
            group_positions, group_radii = clumps.member_positions, clumps.member_radii
            group_velocities, group_spins = clumps.member_velocities, clumps.member_angular_velocities
            count = len(group_radii)
            group_labels = clumps.member_body + body_count
            member_body.append(group_labels)
            member_offsets.append(clumps.member_offsets)
            bodies["group_index"].append(np.full(len(clumps.positions), index, dtype=np.int32))
            for key in ("positions", "orientations", "velocities", "angular_velocities"):
                bodies[key].append(getattr(clumps, key))
            body_count += len(clumps.positions)
        elif insert.kind == "list":
            group_positions = np.array(insert.positions, dtype=float).reshape(-1, 3)
            count = len(group_positions)
            group_radii = (np.array(insert.radii, dtype=float) if insert.radii is not None
                           else _group_radii(group, count, rng))
            group_velocities = (np.array(insert.velocities, dtype=float).reshape(-1, 3)
                                if insert.velocities is not None else np.tile(insert.velocity, (count, 1)))
            group_spins = (np.array(insert.angular_velocities, dtype=float).reshape(-1, 3)
                           if insert.angular_velocities is not None else np.zeros((count, 3)))
        if group.clump is None and insert.kind != "list":
            count = insert.count
            group_radii = _group_radii(group, count, rng)
            group_velocities = np.tile(np.array(insert.velocity, dtype=float), (count, 1))
            group_spins = np.zeros((count, 3))
            if insert.kind == "lattice":
                group_positions = _lattice_positions(group, where, rng)
            else:
                group_positions = _random_positions(group, group_radii, placed_positions, placed_radii, where,
                                                    periodic_box)
        if group_labels is None:
            group_labels = np.full(count, -1, dtype=np.int64)
            member_body.append(group_labels)
            member_offsets.append(np.zeros((count, 3)))
        combined_positions = np.concatenate([placed_positions, group_positions])
        combined_radii = np.concatenate([placed_radii, group_radii])
        combined_labels = np.concatenate([placed_labels, group_labels])
        if insert.kind != "random":
            # Listed positions may carry a settled packing's contact overlaps (1e-3..1e-2 radii), as against a
            # wall (pdemfem.scene.inputs); deeper ones would shoot the pair apart at step 0.
            overlap = first_overlap(combined_positions, combined_radii, combined_labels,
                                    START_OVERLAP_TOLERANCE if insert.kind == "list" else OVERLAP_TOLERANCE,
                                    periodic_box)
            if overlap is not None:
                raise SceneError(where, _describe_overlap(scene, overlap, combined_positions, combined_radii,
                                                          insert.kind == "list", periodic_box),
                                 "move the positions apart (distance >= sum of radii) or shrink the radii"
                                 if group.clump is None else
                                 "move the clumps apart (their spheres must not overlap another clump's), or turn "
                                 "them (orientations)")
        placed_positions, placed_radii, placed_labels = combined_positions, combined_radii, combined_labels
        group_index.append(np.full(count, index, dtype=np.int32))
        radii.append(group_radii)
        positions.append(group_positions)
        velocities.append(group_velocities)
        spins.append(group_spins)
    if not radii:
        empty = np.zeros((0, 3))
        return InsertedParticles(np.zeros(0, dtype=np.int32), np.zeros(0), empty, empty.copy(), empty.copy(),
                                 np.zeros(0, dtype=np.int64), empty.copy())
    clumps = None
    if body_count:
        clumps = InsertedClumps(np.concatenate(bodies["group_index"]),
                                *(np.concatenate(bodies[key]) for key in ("positions", "orientations", "velocities",
                                                                          "angular_velocities")), templates)
    return InsertedParticles(np.concatenate(group_index), np.concatenate(radii), np.concatenate(positions),
                             np.concatenate(velocities), np.concatenate(spins), np.concatenate(member_body),
                             np.concatenate(member_offsets), clumps)


def _random_positions(group, radii, placed_positions, placed_radii, where, periodic_box=None):
    insert = group.insert
    low, high = (np.array(corner, dtype=float) for corner in insert.region.box)
    if periodic_box is not None and len(placed_radii):
        # The earlier groups' particles near a periodic face also stand beyond the opposite one.
        placed_positions, placed_radii, _ = periodic_box.with_images(
            placed_positions, placed_radii, 2.0 * float(max(radii.max(), placed_radii.max())))
    largest = float(max(radii.max(), placed_radii.max() if len(placed_radii) else 0.0))
    if np.any(high - low < 2.0 * radii.max()):
        raise SceneError(f"{where}.region.box", "the region is thinner than one particle diameter",
                         "enlarge region.box")
    grid_lower = np.minimum(low, placed_positions.min(axis=0) if len(placed_positions) else low)
    grid_upper = np.maximum(high, placed_positions.max(axis=0) if len(placed_positions) else high)
    cell_size = 2.0 * largest
    dimensions = (np.floor((grid_upper - grid_lower) / cell_size).astype(np.int64) + 1)
    positions, placed = _random_place(low, high, radii, placed_positions, placed_radii, cell_size, dimensions,
                                      grid_lower, insert.max_attempts, insert.seed)
    if placed < len(radii):
        solid_fraction = (4.0 / 3.0 * np.pi * np.sum(radii**3)) / np.prod(high - low)
        raise SceneError(f"{where}.count",
                         f"random insertion placed only {placed} of {len(radii)} particles "
                         f"(requested solid fraction {solid_fraction:.2f}; random packings jam near 0.3-0.38)",
                         "enlarge region.box, reduce count, raise max_attempts, or use kind: lattice")
    return positions


def _describe_overlap(scene, overlap, positions, radii, listed=False, periodic_box=None):
    i, j = overlap
    separation = positions[i] - positions[j]
    through = ""
    if periodic_box is not None:
        nearest = periodic_box.nearest_separation(separation)
        if not np.allclose(nearest, separation):
            through = " through a periodic face"
        separation = nearest
    distance = float(np.linalg.norm(separation))
    allowed = (f", by more than the {START_OVERLAP_TOLERANCE:g} of the smaller radius a settled packing's contacts "
               f"may start with" if listed else "")
    return (f"particles {i} and {j} overlap at insertion{through} (centre distance {distance:g} m < "
            f"radius sum {radii[i] + radii[j]:g} m{allowed}; indices count across groups in scene order)")

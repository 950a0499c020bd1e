"""Triangle-mesh walls: a triangle surface the particles touch, rigid (MeshWall) or deformable.

`TriangleSurface` is the part both kinds share and a ParticleSystem *contributor*
(name, move(dt), add_forces(system, first, last), local_totals(), take_summed_totals(summed)):

    surface = TriangleSurface("plate", vertices, triangles, material_index)
    surface.set_vertices(positions, velocities)   # any time, e.g. every step from the FE nodes
    ... ParticleSystem(..., contributors=[surface])
    surface.force, surface.torque(about)           # totals on the surface, summed over ranks
    surface.contacts                               # this rank's contacts: particle, triangle,
                                                   # barycentric weights, point, force on the surface
    surface.vertex_forces                          # (spread_to_vertices=True) this rank's contact
                                                   # forces on the vertices by the barycentric weights

Pipeline per step: (1) when the vertices moved, the BVH is *refit* (never rebuilt
unless it degraded), lazily, only when a candidate list is rebuilt; (2) each
particle keeps a candidate list of the triangles within radius + skin, rebuilt
only when the largest particle displacement plus the largest vertex displacement
since the last build reaches the skin (or the particles were reordered); (3) the
sphere-triangle kernel (pdemfem.walls.triangle_contact) makes one contact per
smooth patch and applies the shared contact law.

Patches: triangles sharing an edge whose normals differ by less than
`smooth_angle` (orientation-aware) are one patch; patch ids are topological, so a
flat plate stays one patch while it deforms.  A caller may pass its own `patch`.

`MeshWall` is a rigid TriangleSurface read from a file with a prescribed velocity
and angular velocity about a moving centre.

Conveyor (`transport_velocity`): the contact law sees the surface moving with the part of that
velocity along the contact's tangent plane while the triangles stay where they are (a belt);
the work it does on the particles is booked with the wall's work.
"""
from __future__ import annotations

import math
from types import SimpleNamespace

import numpy as np
from numba import njit

from pdemfem import state_dict as kinds
from pdemfem.walls.base import ContributorWall, rotation_matrix
from pdemfem.walls.bvh import BVH
from pdemfem.walls.triangle_contact import (DAMPING_RECORD_COLUMNS, largest_displacement,
                                           mesh_contact_forces)

# History slots per particle and mesh: the most patches one sphere touches at once with history
# (a sphere in a box corner touches 3); a 5th simultaneous contact would run without history.
DEFAULT_SLOTS = 4


# --------------------------------------------------------------------------- patches


@njit(cache=True)
def _find(parent, k):
    while parent[k] != k:
        parent[k] = parent[parent[k]]
        k = parent[k]
    return k


@njit(cache=True)
def _merge_smooth_neighbours(edge_keys, edge_triangle, edge_direction, normals, cosine, parent):
    """Union triangles that share an edge (consecutive equal keys) and meet at less than the angle."""
    count = edge_keys.shape[0]
    start = 0
    while start < count:
        end = start + 1
        while end < count and edge_keys[end, 0] == edge_keys[start, 0] and edge_keys[end, 1] == edge_keys[start, 1]:
            end += 1
        for p in range(start, end):
            for q in range(p + 1, end):
                s = edge_triangle[p]
                t = edge_triangle[q]
                # Consistently oriented neighbours run the shared edge in opposite directions.
                orientation = -edge_direction[p] * edge_direction[q]
                dot = orientation * (normals[s, 0] * normals[t, 0] + normals[s, 1] * normals[t, 1]
                                     + normals[s, 2] * normals[t, 2])
                if dot >= cosine:
                    root_s = _find(parent, s)
                    root_t = _find(parent, t)
                    if root_s != root_t:
                        parent[max(root_s, root_t)] = min(root_s, root_t)
        start = end


def smooth_patches(vertices, triangles, smooth_angle: float = 1.0) -> np.ndarray:
    """Patch id (0, 1, ...) of each triangle: edge-connected triangles meeting at < smooth_angle degrees."""
    vertices = np.asarray(vertices, dtype=np.float64)
    triangles = np.asarray(triangles, dtype=np.int64)
    count = len(triangles)
    if count == 0:
        return np.zeros(0, dtype=np.int32)
    a, b, c = (vertices[triangles[:, k]] for k in range(3))
    normals = np.cross(b - a, c - a)
    lengths = np.linalg.norm(normals, axis=1)
    normals = normals / np.where(lengths > 0, lengths, 1.0)[:, None]
    start = triangles.reshape(-1)
    end = triangles[:, [1, 2, 0]].reshape(-1)
    keys = np.stack([np.minimum(start, end), np.maximum(start, end)], axis=1)
    direction = np.where(start < end, 1, -1).astype(np.int64)
    owner = np.repeat(np.arange(count), 3)
    order = np.lexsort((keys[:, 1], keys[:, 0]))
    # A floor of 1e-4 degrees keeps exactly coplanar triangles together despite round-off.
    cosine = math.cos(math.radians(max(float(smooth_angle), 1e-4)))
    parent = np.arange(count, dtype=np.int64)
    _merge_smooth_neighbours(np.ascontiguousarray(keys[order]), np.ascontiguousarray(owner[order]),
                             np.ascontiguousarray(direction[order]), np.ascontiguousarray(normals), cosine, parent)
    roots = _roots(parent)
    _, patch = np.unique(roots, return_inverse=True)
    return patch.astype(np.int32)


@njit(cache=True)
def _roots(parent):
    roots = np.empty(parent.shape[0], dtype=np.int64)
    for k in range(parent.shape[0]):
        roots[k] = _find(parent, k)
    return roots


def vertex_patch_table(triangles, patch, vertex_count: int):
    """CSR (offsets, patches): the patches each vertex belongs to."""
    triangles = np.asarray(triangles, dtype=np.int64)
    pairs = np.unique(np.stack([triangles.reshape(-1), np.repeat(patch, 3)], axis=1), axis=0) \
        if len(triangles) else np.zeros((0, 2), dtype=np.int64)
    offsets = np.zeros(vertex_count + 1, dtype=np.int64)
    np.add.at(offsets, pairs[:, 0] + 1, 1)
    return np.cumsum(offsets), np.ascontiguousarray(pairs[:, 1], dtype=np.int32)


def same_patch_edge_neighbours(triangles, patch) -> np.ndarray:
    """(n, 3): the triangle across edge ab, bc, ca of each triangle within its patch, -1 on the patch's boundary."""
    triangles = np.asarray(triangles, dtype=np.int64)
    count = len(triangles)
    first = triangles
    second = np.roll(triangles, -1, axis=1)          # columns: ab, bc, ca
    keys = np.stack([np.minimum(first, second), np.maximum(first, second)], axis=2).reshape(-1, 2)
    owner = np.repeat(np.arange(count), 3)
    order = np.lexsort((owner, keys[:, 1], keys[:, 0]))
    neighbours = np.full(3 * count, -1, dtype=np.int32)
    sorted_keys = keys[order]
    same = np.all(sorted_keys[1:] == sorted_keys[:-1], axis=1)
    # An edge shared by exactly two triangles (a manifold edge) of one patch.
    for k in np.flatnonzero(same):
        left, right = order[k], order[k + 1]
        if (k + 2 < len(order) and same[k + 1]) or (k > 0 and same[k - 1]):
            continue
        if patch[owner[left]] == patch[owner[right]]:
            neighbours[left] = owner[right]
            neighbours[right] = owner[left]
    return neighbours.reshape(count, 3)


class TriangleSurface(ContributorWall):
    """Triangles the particles touch; vertices may move every step (see module docstring)."""

    def __init__(self, name: str, vertices, triangles, material_index: int, velocities=None, patch=None,
                 smooth_angle: float = 1.0, one_sided: bool = False, skin=None, slots: int = DEFAULT_SLOTS,
                 spread_to_vertices: bool = False, blended: bool = False, transport_velocity=(0.0, 0.0, 0.0),
                 work_of_transport_only: bool = False):
        super().__init__(name)
        # A solid's surface: its own motion exchanges work with the particles inside the system, so `work`
        # books only what the transport velocity does (the belt drive's work).
        self.work_of_transport_only = bool(work_of_transport_only)
        # Conveyor: the surface material moves with this velocity along the surface; the geometry stays.
        self.transport_velocity = np.asarray(transport_velocity, dtype=np.float64).reshape(3).copy()
        self.vertices = np.ascontiguousarray(vertices, dtype=np.float64).reshape(-1, 3).copy()
        self.triangles = np.ascontiguousarray(triangles, dtype=np.int32).reshape(-1, 3)
        self.vertex_velocities = (np.zeros_like(self.vertices) if velocities is None
                                  else np.ascontiguousarray(velocities, dtype=np.float64).reshape(-1, 3).copy())
        self.material_index = int(material_index)
        self.patch = (smooth_patches(self.vertices, self.triangles, smooth_angle) if patch is None
                      else np.ascontiguousarray(patch, dtype=np.int32))
        self.vertex_patch_offsets, self.vertex_patches = vertex_patch_table(self.triangles, self.patch,
                                                                             len(self.vertices))
        self.one_sided = bool(one_sided)
        # Blended contact gap (pdemfem.walls.triangle_contact): its elastic nodal forces land in vertex_forces.
        self.blended = bool(blended)
        self.edge_neighbours = (same_patch_edge_neighbours(self.triangles, self.patch) if self.blended
                                else np.zeros((0, 3), dtype=np.int32))
        self._blend_gradient = np.zeros(3)
        self.skin = skin
        self.slots = int(slots)
        self.spread_to_vertices = bool(spread_to_vertices)
        self.vertex_forces = np.zeros_like(self.vertices)
        # With heat on: the surface temperature [K] at each vertex (empty: adiabatic), and, when the surface
        # is a solid's (its coupling takes it; a rigid wall's is empty: not collected), the heat [J] the
        # contacts sent into each vertex since it was last cleared.
        self.vertex_temperatures = np.zeros(0)
        self.vertex_heat = np.zeros(0)
        self.bvh = BVH(self.vertices, self.triangles)
        self.list_builds = 0
        self.contact_count = 0
        self._bvh_current = True
        self._vertices_moved = False
        self._list_key = None
        self._records = None
        self._allocate_records(0)

    @property
    def patch_count(self) -> int:
        return int(self.patch.max()) + 1 if len(self.patch) else 0

    # ------------------------------------------------------------ kinematics
    def set_vertices(self, positions, velocities=None) -> None:
        """New vertex positions (and velocities, for the contact's relative velocity); topology unchanged."""
        self.vertices[:] = positions
        if velocities is not None:
            self.vertex_velocities[:] = velocities
        self._bvh_current = False
        self._vertices_moved = True

    def move(self, dt: float) -> None:
        """A surface driven from outside (set_vertices) does not move by itself."""

    def set_temperature(self, temperature) -> None:
        """The surface temperature [K]: one value (a wall held at it) or one per vertex (a solid's surface)."""
        values = np.broadcast_to(np.asarray(temperature, dtype=float), (len(self.vertices),))
        self.temperature = float(values[0]) if np.ndim(temperature) == 0 else math.nan
        self.vertex_temperatures = np.ascontiguousarray(values, dtype=float).copy()

    # ------------------------------------------------------------ checkpoints
    def state_dict(self) -> dict:
        state = super().state_dict()
        state["vertices"] = kinds.global_array(self.vertices)
        state["vertex_velocities"] = kinds.global_array(self.vertex_velocities)
        return state

    def load_state_dict(self, state: dict) -> None:
        super().load_state_dict(state)
        vertices = np.asarray(state["vertices"])
        if vertices.shape != self.vertices.shape:
            raise kinds.StateMismatch(f"wall '{self.name}' has {len(vertices)} vertices in the checkpoint, "
                                      f"{len(self.vertices)} in this scene")
        self.set_vertices(vertices, state["vertex_velocities"])

    def canonicalize(self) -> None:
        """The search structure rebuilt from the current vertices alone and no candidate list kept, as a
        restart from a checkpoint of this step has them (the candidates are rebuilt on first use)."""
        self.bvh.build(self.vertices)
        self._bvh_current = True
        self._list_key = None

    # ------------------------------------------------------------ candidate lists
    def _allocate_records(self, capacity: int) -> None:
        capacity = max(int(capacity), 1)
        self._records = SimpleNamespace(
            particle=np.zeros(capacity, dtype=np.int64), triangle=np.zeros(capacity, dtype=np.int32),
            weights=np.zeros((capacity, 3)), point=np.zeros((capacity, 3)), force=np.zeros((capacity, 3)),
            damping=np.zeros((capacity, DAMPING_RECORD_COLUMNS)),
            # The blended contacts' springs over the blended facets' vertices (triangle_contact.mesh_contact_forces):
            # at most 3 rows per candidate triangle.
            share_contact=np.zeros(3 * capacity if self.blended else 0, dtype=np.int64),
            share_vertex=np.zeros(3 * capacity if self.blended else 0, dtype=np.int64),
            share_value=np.zeros(3 * capacity if self.blended else 0))
        self.share_count = 0

    def _lists_valid(self, state, first: int, last: int, skin: float) -> bool:
        if self._list_key != (id(state.ids), state.count, first, last):
            return False
        moved = largest_displacement(state.positions, self._positions_at_build, first, last)
        if self._vertices_moved:
            moved += largest_displacement(self.vertices, self._vertices_at_build, 0, len(self.vertices))
        return moved < skin

    def _rebuild_lists(self, state, first: int, last: int, skin: float, history_width: int,
                       cohesion_reach: float) -> None:
        if not self._bvh_current:
            self.bvh.refit(self.vertices)
            self._bvh_current = True
        reach = state.radii + skin + cohesion_reach
        self.candidate_offsets, self.candidate_triangles = self.bvh.query(self.vertices, state.positions, reach,
                                                                           first, last)
        self._positions_at_build = state.positions.copy()
        self._vertices_at_build = self.vertices.copy()
        self._vertices_moved = False
        # Keep a reference to the ids array: ParticleState.reorder replaces it, which invalidates the lists.
        self._ids_at_build = state.ids
        self._list_key = (id(state.ids), state.count, first, last)
        longest = int(np.max(np.diff(self.candidate_offsets))) if state.count else 0
        self._scratch_int = np.zeros((max(longest, 1), 5), dtype=np.int64)
        self._scratch_float = np.zeros((max(longest, 1), 8))
        self._spare_history = np.zeros((1, history_width + 1))
        if len(self._records.particle) < len(self.candidate_triangles):
            self._allocate_records(len(self.candidate_triangles))
        self.list_builds += 1

    # ------------------------------------------------------------ contributor interface
    def add_forces(self, system, first: int, last: int):
        state, tables = system.state, system.tables
        slot_patch = self._field(state, f"wall:{self.name}:patch", (self.slots,), np.int32, -1)
        # Per slot: the contact history, then the last step's overlap (what an opening contact held).
        slot_history = self._field(state, f"wall:{self.name}:history", (self.slots, tables.history_width + 1),
                                   np.float64, 0.0)
        skin = float(self.skin if self.skin is not None else system.skin)
        if not self._lists_valid(state, first, last, skin):
            self._rebuild_lists(state, first, last, skin, tables.history_width, tables.cohesion_reach)
        self.totals[:] = 0.0
        if self.spread_to_vertices or self.blended:
            self.vertex_forces[:] = 0.0
        records = self._records
        temperatures, heat_flows = self._heat_arrays(state)
        elastic, dissipated, contacts, work, self.step_heat, self.share_count, deepest = mesh_contact_forces(
            first, last, self.candidate_offsets, self.candidate_triangles,
            self.vertices, self.vertex_velocities, self.triangles, self.patch,
            self.vertex_patch_offsets, self.vertex_patches, self.one_sided, self.material_index,
            slot_patch, slot_history, self.blended, self._blend_gradient, self.edge_neighbours,
            state.positions, state.velocities, state.angular_velocities, state.radii, state.mass,
            state.inverse_inertia, state.material_index, tables.coefficients, tables.composition,
            tables.cohesion_reach, system.dt, state.forces, state.torques, self.totals, self.spread_to_vertices, self.vertex_forces,
            records.particle, records.triangle, records.weights, records.point, records.force, records.damping,
            records.share_contact, records.share_vertex, records.share_value, self._scratch_int, self._scratch_float, self._spare_history, self.transport_velocity,
            temperatures, heat_flows, self.vertex_temperatures, self.vertex_heat)
        self.contact_count = int(contacts)
        # The run monitor's overlap test (pdemfem.monitor, test 5): a centre reaching the surface passes through it.
        if deepest > system.deepest_overlaps[2]:
            system.deepest_overlaps[2] = deepest
        if self.work_of_transport_only:
            work = self._transport_work(system.dt)
        self._step_work = float(work)
        if system.comm.size == 1:
            self._book_step_work(self._step_work)
        return elastic, dissipated, contacts

    def _transport_work(self, dt: float) -> float:
        """Work [J] of this step's contact forces on the particles times the transport velocity's part
        along each contact's tangent plane (the contact records hold the force on the surface and n)."""
        contacts = self.contacts
        if not len(contacts.particle) or not np.any(self.transport_velocity):
            return 0.0
        normals = contacts.damping[:, 2:5]
        tangential = self.transport_velocity - (normals @ self.transport_velocity)[:, None] * normals
        return -float(np.sum(contacts.force * tangential)) * dt

    @property
    def contacts(self) -> SimpleNamespace:
        """This rank's contacts of the last force evaluation (views): particle index, triangle,
        barycentric weights of the contact point, contact point, force on the surface, and the
        dashpot record (c_n, c_t, normal, lever, particle and surface velocity at the contact point), and the
        blended contacts' spring shares (share_contact: the contact's row, share_vertex, share_value: S_n b_v)."""
        n = min(self.contact_count, len(self._records.particle))
        r = self._records
        shares = self.share_count
        return SimpleNamespace(particle=r.particle[:n], triangle=r.triangle[:n], weights=r.weights[:n],
                               point=r.point[:n], force=r.force[:n], damping=r.damping[:n],
                               share_contact=r.share_contact[:shares], share_vertex=r.share_vertex[:shares],
                               share_value=r.share_value[:shares])


class MeshWall(TriangleSurface):
    """A rigid triangle mesh moving with `velocity` and rotating with `angular_velocity` about `center`
    (the centre moves with the velocity).  Vertex positions are recomputed from the reference
    configuration every step (no drift), vertex velocities are v + w x (x - centre)."""

    def __init__(self, name: str, vertices, triangles, material_index: int, velocity=(0.0, 0.0, 0.0),
                 angular_velocity=(0.0, 0.0, 0.0), center=(0.0, 0.0, 0.0), **options):
        self.reference_vertices = np.ascontiguousarray(vertices, dtype=np.float64).reshape(-1, 3).copy()
        self.velocity = np.asarray(velocity, dtype=float).reshape(3)
        self.angular_velocity = np.asarray(angular_velocity, dtype=float).reshape(3)
        self.reference_center = np.asarray(center, dtype=float).reshape(3)
        self.time = 0.0
        super().__init__(name, self.reference_vertices, triangles, material_index,
                         velocities=self._vertex_velocities(self.reference_vertices, self.reference_center),
                         **options)

    @property
    def moving(self) -> bool:
        return bool(np.any(self.velocity) or np.any(self.angular_velocity))

    def state_dict(self) -> dict:
        state = super().state_dict()
        state["time"] = kinds.scalar(float(self.time))
        return state

    def load_state_dict(self, state: dict) -> None:
        super().load_state_dict(state)
        self.time = float(state["time"])

    @property
    def center(self) -> np.ndarray:
        return self.reference_center + self.time * self.velocity

    def _vertex_velocities(self, positions, center):
        return self.velocity + np.cross(self.angular_velocity, positions - center)

    def move(self, dt: float) -> None:
        if not self.moving:
            return
        self.time += dt
        center = self.center
        rotation = rotation_matrix(self.angular_velocity * self.time)
        positions = center + (self.reference_vertices - self.reference_center) @ rotation.T
        self.set_vertices(positions, self._vertex_velocities(positions, center))

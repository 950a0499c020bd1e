"""METIS partition of the cells, contiguous node renumbering, and each rank's local mesh.

Rank 0 reads the global mesh, partitions it and sends every rank only what it
needs (setup-time, once; the object messages are small dicts of numpy arrays):

- nodes are renumbered so rank r owns the contiguous block node_range[r];
  a node belongs to the rank of the lowest-numbered cell that contains it;
- a rank's local cells are its METIS cells ("owned cells", first) followed by
  the other cells touching one of its owned nodes ("halo cells"); assembling
  owned rows from these needs no communication and gives exact preallocation;
- local nodes are the owned nodes (first, ascending) followed by the ghosts
  (every other node of a local cell, ascending global number).

The whole mesh passes through rank 0's memory: fine to a few million cells;
a distributed reader (gmsh partitioned .msh + ParMETIS) replaces it beyond.
"""
from __future__ import annotations

from dataclasses import dataclass, field

import numpy as np

from pdemfem.errors import MeshError, PdemfemError
from pdemfem.fem.elements import p2_connectivity, edge_midside_nodes
from pdemfem.fem.mesh import GlobalMesh
from pdemfem.fem.regions import region_node_groups


@dataclass
class LocalMesh:
    source: str
    element: str  # "P1" or "P2"
    n_global_nodes: int
    node_range: tuple  # (first, end) global numbers of the owned nodes
    ghost_nodes: np.ndarray  # global numbers of the ghosts, ascending
    points: np.ndarray  # (n_local, 3) owned then ghosts
    cells: np.ndarray  # (n_local_cells, nen) local node numbers, owned cells first
    n_owned_cells: int
    n_global_cells: int
    original_node_ids: np.ndarray  # owned nodes' numbers in the input (P2 midsides: corners + edge index)
    original_cell_ids: np.ndarray  # owned cells' numbers in the input
    group_faces: dict = field(default_factory=dict)  # name -> local faces (3 or 6 nodes) touching owned nodes
    group_nodes: dict = field(default_factory=dict)  # name -> owned local node numbers on the group
    contact_faces: dict = field(default_factory=dict)  # name -> all faces of a contact group, global numbers
    # The same faces in the input's node numbering (P2 midsides: corners + edge index): the rank-count independent
    # order of a contact surface's nodes (checkpoints written on one rank count are read on another).
    contact_faces_input: dict = field(default_factory=dict)
    point_nodes: np.ndarray = None  # global node nearest to each requested point
    bounding_box: np.ndarray = None  # (2, 3)

    @property
    def n_owned_nodes(self) -> int:
        return self.node_range[1] - self.node_range[0]

    @property
    def n_local_nodes(self) -> int:
        return len(self.points)

    @property
    def local_to_global(self) -> np.ndarray:
        first, end = self.node_range
        return np.concatenate([np.arange(first, end, dtype=np.int64), self.ghost_nodes])


def partition_cells(tets: np.ndarray, n_parts: int) -> np.ndarray:
    """METIS dual-graph partition (cells sharing a face are neighbours); deterministic."""
    if n_parts == 1:
        return np.zeros(len(tets), dtype=np.int64)
    if len(tets) < n_parts:
        raise MeshError(where="mesh", problem=f"{len(tets)} cells cannot be split over {n_parts} ranks", fix="use fewer ranks or a finer mesh")
    import pymetis

    options = pymetis.Options(seed=0)
    result = pymetis.part_mesh(n_parts, tets, options=options, gtype=pymetis.GType.DUAL, ncommon=3)
    part = np.asarray(result.element_part, dtype=np.int64)
    if len(np.unique(part)) != n_parts:  # METIS may leave a part empty on tiny meshes
        part = (np.arange(len(tets)) * n_parts) // len(tets)
    return part


def _face_nodes(mesh: GlobalMesh, faces: np.ndarray, element: str, edges, n_corners) -> np.ndarray:
    if element == "P1":
        return faces
    a, b, c = faces[:, 0], faces[:, 1], faces[:, 2]
    mids = [edge_midside_nodes(edges, n_corners, np.column_stack(pair)) for pair in ((a, b), (b, c), (c, a))]
    return np.column_stack([faces, *mids])


def build_partition(mesh: GlobalMesh, element: str, n_parts: int, group_names, contact_names, points_of_interest,
                    regions=None, region_key="regions"):
    """Rank 0: one dict of local-mesh arrays per rank.  regions: name -> RegionConfig, node groups
    (no faces) chosen by geometry (pdemfem.fem.regions); region_key names them in errors."""
    n_corners = len(mesh.points)
    edges = None
    if element == "P2":
        points, cells, edges = p2_connectivity(mesh.points, mesh.tets)
    else:
        points, cells = mesh.points, mesh.tets
    n_nodes, n_cells = len(points), len(cells)
    nen = cells.shape[1]
    regions = regions or {}
    region_nodes = region_node_groups(points, mesh.tets, regions, region_key, mesh.face_groups)
    faces_of = {name: _face_nodes(mesh, mesh.group_faces(name), element, edges, n_corners)
                for name in (set(group_names) | set(contact_names)) - set(regions)}

    part = partition_cells(mesh.tets, n_parts)
    first_cell = np.full(n_nodes, n_cells, dtype=np.int64)
    np.minimum.at(first_cell, cells.ravel(), np.repeat(np.arange(n_cells, dtype=np.int64), nen))
    owner = part[first_cell]
    node_order = np.lexsort((np.arange(n_nodes), owner))
    new_of_old = np.empty(n_nodes, dtype=np.int64)
    new_of_old[node_order] = np.arange(n_nodes)
    counts = np.bincount(owner, minlength=n_parts)
    starts = np.concatenate([[0], np.cumsum(counts)])
    cell_order = np.lexsort((np.arange(n_cells), part))
    new_cells = new_of_old[cells[cell_order]]
    cell_part = part[cell_order]
    new_points = points[node_order]
    owner_new = owner[node_order]
    faces_new = {name: new_of_old[faces] for name, faces in faces_of.items()}
    contact_new = {name: faces_new[name] for name in contact_names}
    region_nodes_new = {name: np.sort(new_of_old[nodes]) for name, nodes in region_nodes.items()}
    face_width = 3 if element == "P1" else 6
    if len(points_of_interest):
        targets = np.asarray(points_of_interest, float)
        nearest = [int(np.argmin(np.sum((points - t) ** 2, axis=1))) for t in targets]
        point_nodes = new_of_old[np.array(nearest, dtype=np.int64)]
    else:
        point_nodes = np.zeros(0, dtype=np.int64)
    bounding_box = np.array([points.min(axis=0), points.max(axis=0)])

    payloads = []
    cell_owners = owner_new[new_cells]  # (nc, nen)
    for rank in range(n_parts):
        first, end = int(starts[rank]), int(starts[rank + 1])
        owned = np.flatnonzero(cell_part == rank)
        halo = np.flatnonzero((cell_part != rank) & np.any(cell_owners == rank, axis=1))
        local_cells_global = new_cells[np.concatenate([owned, halo])]
        used = np.unique(local_cells_global)
        ghosts = used[(used < first) | (used >= end)]

        def to_local(global_ids, first=first, end=end, ghosts=ghosts):
            global_ids = np.asarray(global_ids, dtype=np.int64)
            local = global_ids - first
            outside = (global_ids < first) | (global_ids >= end)
            local[outside] = (end - first) + np.searchsorted(ghosts, global_ids[outside])
            return local

        l2g = np.concatenate([np.arange(first, end, dtype=np.int64), ghosts])
        group_faces, group_nodes = {}, {}
        for name, faces in faces_new.items():
            touching = np.any((faces >= first) & (faces < end), axis=1)
            group_faces[name] = to_local(faces[touching]).reshape(-1, faces.shape[1])
            nodes = np.unique(faces)
            group_nodes[name] = nodes[(nodes >= first) & (nodes < end)] - first
        for name, nodes in region_nodes_new.items():  # a region is nodes only: no faces
            group_faces[name] = np.zeros((0, face_width), dtype=np.int64)
            group_nodes[name] = nodes[(nodes >= first) & (nodes < end)] - first
        payloads.append(
            dict(
                source=mesh.source,
                element=element,
                n_global_nodes=n_nodes,
                node_range=(first, end),
                ghost_nodes=ghosts,
                points=new_points[l2g],
                cells=to_local(local_cells_global.ravel()).reshape(-1, nen),
                n_owned_cells=len(owned),
                n_global_cells=n_cells,
                original_node_ids=node_order[first:end],
                original_cell_ids=cell_order[owned],
                group_faces=group_faces,
                group_nodes=group_nodes,
                contact_faces=contact_new,
                contact_faces_input={name: faces_of[name] for name in contact_names},
                point_nodes=point_nodes,
                bounding_box=bounding_box,
            )
        )
    return payloads


def mesh_description(exc: Exception) -> str:
    return f"{type(exc).__name__}: {exc}"


def distribute_mesh(comm, load_global_mesh, element: str, group_names, contact_names, points_of_interest=(),
                    regions=None, region_key="regions") -> LocalMesh:
    """Collective: rank 0 calls load_global_mesh() and partitions; every rank gets its LocalMesh.

    A MeshError on rank 0 is raised on every rank, so all exit together.
    """
    payloads, error = None, None
    if comm.rank == 0:
        try:
            payloads = build_partition(load_global_mesh(), element, comm.size, group_names, contact_names,
                                       points_of_interest, regions, region_key)
        except PdemfemError as exc:
            error = (type(exc).__name__, exc.where, exc.problem, exc.fix)
        except Exception as exc:  # a bug must not leave the other ranks waiting in bcast
            error = ("RuntimeError", mesh_description(exc), "", "")
    error = comm.bcast(error, root=0)
    if error is not None:
        import pdemfem.errors as errors

        if error[0] == "RuntimeError":
            raise RuntimeError(f"mesh setup failed on rank 0: {error[1]}")
        raise getattr(errors, error[0])(where=error[1], problem=error[2], fix=error[3])
    return LocalMesh(**comm.scatter(payloads, root=0))

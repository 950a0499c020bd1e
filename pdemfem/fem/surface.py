"""Contact surfaces: the triangles particles may touch, and the gathers of their nodes' state.

The triangles (global node numbers; a P2 face is split into 4 flat triangles)
are identical on every rank.  A `NodeGather` brings a set of surface nodes'
displacements and velocities (or a nodal scalar such as the temperature) to the
rank that asks, with one PETSc VecScatter from the nodes' owners; creating one is
collective, using it is collective too.

`ContactSurface.gather` / `gather_scalar` use the *whole* gather (every surface
node to every rank: 6 doubles per surface node and rank, O(total surface nodes)
per rank).  `ContactSurface.select(rows)` makes a gather of a subset: the DEM
coupling (pdemfem.coupling.surface) gives each rank only the nodes of the
triangles near its own particles, so its cost per rank follows that rank's
share of the surface (docs/parallel.md, "The FE side and the coupled step").
"""
from __future__ import annotations

import numpy as np
from pdemfem.fem.petsc import PETSc

from pdemfem.fem.elements import split_p2_faces


class NodeGather:
    """Collective to create: the state of the surface nodes `rows` (indices into ContactSurface.node_indices,
    this rank's own choice) gathered onto this rank from the nodes' owners."""

    def __init__(self, surface: "ContactSurface", rows, layout: PETSc.Vec):
        self.surface = surface
        self.rows = np.ascontiguousarray(rows, dtype=np.int64)
        nodes = surface.node_indices[self.rows].astype(PETSc.IntType)
        self._gathered = PETSc.Vec().createSeq(3 * len(nodes), bsize=3, comm=PETSc.COMM_SELF)
        self._gathered_second = self._gathered.duplicate()
        source = PETSc.IS().createBlock(3, nodes, comm=PETSc.COMM_SELF)
        self._scatter = PETSc.Scatter().create(layout, source, self._gathered, None)
        self._scalar_scatter = None

    def __len__(self) -> int:
        return len(self.rows)

    def vector(self, nodal: PETSc.Vec) -> np.ndarray:
        """Collective: a nodal vector field (block size 3) at the rows, (len(rows), 3)."""
        self._scatter.scatter(nodal, self._gathered, addv=PETSc.InsertMode.INSERT_VALUES,
                              mode=PETSc.ScatterMode.FORWARD)
        return self._gathered.getArray(readonly=True).reshape(-1, 3).copy()

    def pair_views(self, first: PETSc.Vec, second: PETSc.Vec) -> tuple[np.ndarray, np.ndarray]:
        """Collective: two nodal vector fields at the rows as read-only (len(rows), 3) views of this gather's
        buffers, valid until its next call (no copy: the partial refresh reads them once)."""
        for nodal, buffer in ((first, self._gathered), (second, self._gathered_second)):
            self._scatter.scatter(nodal, buffer, addv=PETSc.InsertMode.INSERT_VALUES, mode=PETSc.ScatterMode.FORWARD)
        return (self._gathered.getArray(readonly=True).reshape(-1, 3),
                self._gathered_second.getArray(readonly=True).reshape(-1, 3))

    def scalar(self, nodal: PETSc.Vec) -> np.ndarray:
        """Collective: a nodal scalar field (block size 1, e.g. the temperature) at the rows; the scatter is
        made on first use (collective: every rank asks at the same time)."""
        if self._scalar_scatter is None:
            self._scalar_gathered = PETSc.Vec().createSeq(len(self.rows), comm=PETSc.COMM_SELF)
            source = PETSc.IS().createGeneral(self.surface.node_indices[self.rows].astype(PETSc.IntType),
                                              comm=PETSc.COMM_SELF)
            self._scalar_scatter = PETSc.Scatter().create(nodal, source, self._scalar_gathered, None)
        self._scalar_scatter.scatter(nodal, self._scalar_gathered, addv=PETSc.InsertMode.INSERT_VALUES,
                                     mode=PETSc.ScatterMode.FORWARD)
        return self._scalar_gathered.getArray(readonly=True).copy()

    def state(self, displacement: PETSc.Vec, velocity: PETSc.Vec) -> tuple[np.ndarray, np.ndarray]:
        """Collective: (positions X + u, velocities) of the rows, (len(rows), 3) each (the solid's own axes)."""
        return self.surface.reference_positions[self.rows] + self.vector(displacement), self.vector(velocity)


def _triangles(faces_by_group: dict, groups) -> np.ndarray:
    """The groups' faces as flat triangles (a P2 face split into 4), in group and face order."""
    faces = [faces_by_group[name] for name in groups]
    faces = np.vstack(faces) if faces else np.zeros((0, 3), dtype=np.int64)
    return np.ascontiguousarray(split_p2_faces(faces) if faces.shape[1] == 6 else faces, dtype=np.int64)


class ContactSurface:
    def __init__(self, faces_by_group: dict, groups, reference_coordinates: PETSc.Vec, input_faces_by_group=None):
        """Collective. reference_coordinates: undeformed nodal positions, laid out like the displacement Vec.
        input_faces_by_group: the same faces in the input's node numbering; the surface's nodes are then in the
        order of their input numbers, the same on any rank count (else in the order of their global numbers,
        which the partition renumbers: a checkpoint's per-vertex arrays would not fit another rank count)."""
        self.groups = tuple(groups)
        self.triangles_global = _triangles(faces_by_group, groups)
        if input_faces_by_group is None:
            self.node_indices = np.unique(self.triangles_global)  # global node numbers, ascending
            self.triangles = np.searchsorted(self.node_indices, self.triangles_global)  # into node_indices
        else:
            # The input faces split alike: triangle for triangle, corner for corner the same nodes.
            triangles_input = _triangles(input_faces_by_group, groups)
            input_numbers, first = np.unique(triangles_input, return_index=True)
            self.node_indices = self.triangles_global.ravel()[first]  # global numbers, by input number
            self.triangles = np.searchsorted(input_numbers, triangles_input)
        self._layout = reference_coordinates
        self.reference_positions = np.zeros((len(self.node_indices), 3))
        self.whole = NodeGather(self, np.arange(len(self.node_indices)), reference_coordinates)
        self.reference_positions = self.whole.vector(reference_coordinates)
        # The surface nodes this rank owns in the nodal layout (rows into node_indices, and their local rows).
        first, last = (bound // 3 for bound in reference_coordinates.getOwnershipRange())
        self.owned_rows = np.flatnonzero((self.node_indices >= first) & (self.node_indices < last))
        self.owned_local_rows = self.node_indices[self.owned_rows] - first

    def select(self, rows) -> NodeGather:
        """Collective: a gather of the nodes `rows` (into node_indices) onto this rank (each rank its own rows)."""
        return NodeGather(self, rows, self._layout)

    def owned_values(self, nodal: PETSc.Vec) -> np.ndarray:
        """A nodal vector field (block size 3) at the surface nodes this rank owns (rows owned_rows); no
        communication."""
        return nodal.getArray(readonly=True).reshape(-1, 3)[self.owned_local_rows].copy()

    def local_values(self, nodal: PETSc.Vec) -> np.ndarray:
        """This rank's part of a nodal vector field (block size 3) as a read-only (owned nodes, 3) view."""
        return nodal.getArray(readonly=True).reshape(-1, 3)

    def gather_scalar(self, nodal: PETSc.Vec) -> np.ndarray:
        """Collective: a nodal scalar field (e.g. the temperature, block size 1) at node_indices, on every rank."""
        return self.whole.scalar(nodal)

    def gather(self, displacement: PETSc.Vec, velocity: PETSc.Vec) -> tuple[np.ndarray, np.ndarray]:
        """Collective: (positions, velocities) of node_indices, (n, 3) each, on every rank."""
        return self.whole.state(displacement, velocity)

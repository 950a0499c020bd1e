"""Contact surfaces: the triangles particles may touch, and their nodes' state on every rank.

The triangles (global node numbers; a P2 face is split into 4 flat triangles)
are identical on every rank.  `gather` brings the surface nodes' displacements
and velocities to every rank with one VecScatter (an all-gather of 6 doubles
per surface node per call): it costs O(total surface nodes) per rank and per
coupling step, fine to ~10^5 surface nodes; beyond that each rank should only
gather the triangles near its DEM subdomain (a neighbourhood scatter).
"""
from __future__ import annotations

import numpy as np
from petsc4py import PETSc

from pdemfem.fem.elements import split_p2_faces


class ContactSurface:
    def __init__(self, faces_by_group: dict, groups, reference_coordinates: PETSc.Vec):
        """Collective. reference_coordinates: undeformed nodal positions, laid out like the displacement Vec."""
        faces = [faces_by_group[name] for name in groups]
        faces = np.vstack(faces) if faces else np.zeros((0, 3), dtype=np.int64)
        triangles = split_p2_faces(faces) if faces.shape[1] == 6 else faces
        self.groups = tuple(groups)
        self.triangles_global = np.ascontiguousarray(triangles, dtype=np.int64)
        self.node_indices = np.unique(self.triangles_global)  # global node numbers, ascending
        self.triangles = np.searchsorted(self.node_indices, self.triangles_global)  # into node_indices
        n = len(self.node_indices)
        self._gathered = PETSc.Vec().createSeq(3 * n, bsize=3, comm=PETSc.COMM_SELF)
        source = PETSc.IS().createBlock(3, self.node_indices.astype(PETSc.IntType), comm=PETSc.COMM_SELF)
        self._forward_scatter = PETSc.Scatter().create(reference_coordinates, source, self._gathered, None)
        self.reference_positions = self._gather(reference_coordinates)

    def _gather(self, nodal: PETSc.Vec) -> np.ndarray:
        self._forward_scatter.scatter(nodal, self._gathered, addv=PETSc.InsertMode.INSERT_VALUES,
                                      mode=PETSc.ScatterMode.FORWARD)
        return self._gathered.getArray(readonly=True).reshape(-1, 3).copy()

    def gather_scalar(self, nodal: PETSc.Vec) -> np.ndarray:
        """Collective: a nodal scalar field (e.g. the temperature, block size 1) at node_indices, on every rank."""
        if getattr(self, "_scalar_scatter", None) is None:
            self._scalar_gathered = PETSc.Vec().createSeq(len(self.node_indices), comm=PETSc.COMM_SELF)
            source = PETSc.IS().createGeneral(self.node_indices.astype(PETSc.IntType), comm=PETSc.COMM_SELF)
            self._scalar_scatter = PETSc.Scatter().create(nodal, source, self._scalar_gathered, None)
        self._scalar_scatter.scatter(nodal, self._scalar_gathered, addv=PETSc.InsertMode.INSERT_VALUES,
                                     mode=PETSc.ScatterMode.FORWARD)
        return self._scalar_gathered.getArray(readonly=True).copy()

    def gather(self, displacement: PETSc.Vec, velocity: PETSc.Vec) -> tuple[np.ndarray, np.ndarray]:
        """Collective: (positions, velocities) of node_indices, (n, 3) each, on every rank."""
        return self.reference_positions + self._gather(displacement), self._gather(velocity)

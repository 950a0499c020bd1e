"""A solid's contact surface mirrored into the DEM as a moving triangle surface.

The triangles are the solid's contact-group faces (P2 faces split into four);
their vertices are the FE surface nodes, refreshed from the solid's
displacement and velocity after every FE step.  Contact counter-forces go back
to the owning FE nodes through Solid.add_nodal_forces (PETSc ADD_VALUES), so
every rank adds only the contacts of the particles it owns and each contact is
summed exactly once.
"""
from __future__ import annotations

import numpy as np

from pdemfem.coupling.transfer import (SUB_TRIANGLE_AREA_COORDINATES, parent_faces_from_split, spread_linear,
                                       spread_quadratic)
from pdemfem.walls.mesh import TriangleSurface


class CoupledSurface:
    def __init__(self, solid, material_index: int, smooth_angle: float = 1.0, skin=None):
        self.solid = solid
        self.name = solid.name
        contact = solid.contact_surface()
        self.node_indices = contact.node_indices              # global FE node numbers of the surface nodes
        self.triangles = np.ascontiguousarray(contact.triangles, dtype=np.int64)  # into node_indices
        self.quadratic = solid.config.element == "P2"
        self.parent_faces = parent_faces_from_split(self.triangles) if self.quadratic else None
        _, positions, velocities = solid.surface_state()
        self.triangle_surface = TriangleSurface(self.name, positions, self.triangles, material_index,
                                                velocities=velocities, smooth_angle=smooth_angle, skin=skin)
        self.node_forces = np.zeros((len(self.node_indices), 3))
        # Forces summed over the DEM steps since the last FE advance (sub-cycling).
        self.accumulated_forces = np.zeros_like(self.node_forces)

    def collect_contact_forces(self) -> None:
        """Add this step's contact counter-forces (this rank's contacts) to the accumulator."""
        contacts = self.triangle_surface.contacts
        self.node_forces[:] = 0.0
        if len(contacts.triangle):
            if self.quadratic:
                spread_quadratic(self.parent_faces, SUB_TRIANGLE_AREA_COORDINATES, contacts.triangle,
                                 contacts.weights, contacts.force, self.node_forces)
            else:
                spread_linear(self.triangles, contacts.triangle, contacts.weights, contacts.force, self.node_forces)
        self.accumulated_forces += self.node_forces

    def send_forces_to_solid(self, scale: float) -> None:
        """Add scale x the accumulated forces to the solid's nodal loads (ADD_VALUES to the owners)."""
        loaded = np.flatnonzero(np.any(self.accumulated_forces != 0.0, axis=1))
        self.solid.add_nodal_forces(self.node_indices[loaded], scale * self.accumulated_forces[loaded])
        self.accumulated_forces[:] = 0.0

    def remember_positions(self) -> None:
        """Keep the mirrored positions before an advance (for the mean surface velocity over it)."""
        self._positions_before = self.triangle_surface.vertices.copy()

    def refresh_vertices(self, interval=None) -> None:
        """Collective: mirror the solid's current surface positions, and as velocities the mean over the
        last advance of length `interval` (the displacement increment / interval: the velocity at the
        particles' half step, see driver.py); interval None: the solid's own half-step velocities."""
        _, positions, velocities = self.solid.surface_state()
        if interval is not None and getattr(self, "_positions_before", None) is not None:
            velocities = (positions - self._positions_before) / interval
        self.triangle_surface.set_vertices(positions, velocities)

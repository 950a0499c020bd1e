"""The particle system: state, neighbour list, walls and the step of the DEM.

Parallel model (until spatial decomposition lands): every rank holds all
particles; rank r computes the contacts of the list rows and the wall contacts
of particles in its owned slice, and the forces are summed over ranks with one
buffer Allreduce.  Results equal the serial ones up to summation order.
"""
from __future__ import annotations

import numpy as np
from mpi4py import MPI

from pdemfem.contact.forces import pair_forces, plane_wall_forces
from pdemfem.neighbors.verlet import VerletList
from pdemfem.particles.integrate import drift, kick


class ParticleSystem:
    """DEM state and step.

    Other bodies the particles touch (mesh walls, cylinders, FE surfaces) plug in
    as *contributors*: objects with
      name                                   unique name (for wall_force lookups)
      move(dt)                               advance the body's own kinematics before forces
      add_forces(system, first, last)        add contact forces of particles [first, last) to
                                             system.state.forces/torques; return (elastic, dissipated, contacts)
      reduce(comm)                           sum the body's rank-local totals (called when comm.size > 1)
    Their per-particle contact history lives in state.fields (see ParticleState.add_field),
    so it is reordered and migrated with the particles.
    """

    def __init__(self, state, walls, tables, gravity, dt: float, skin: float, comm, contributors=()):
        self.state = state
        self.walls = walls
        self.tables = tables
        self.gravity = np.asarray(gravity, dtype=float)
        self.dt = float(dt)
        self.skin = float(skin)
        self.comm = comm
        self.neighbors = VerletList()
        self.contributors = list(contributors)
        self.elastic_energy = 0.0
        self.dissipated_energy = 0.0
        self.contact_count = 0
        self._rebuild()
        self._compute_forces()

    # ---------------------------------------------------------------- ownership
    def owned_range(self) -> tuple:
        """[first, last) of the particles this rank owns in the current order."""
        count, size, rank = self.state.count, self.comm.size, self.comm.rank
        return count * rank // size, count * (rank + 1) // size

    # ---------------------------------------------------------------- the step
    def step(self) -> None:
        state, dt = self.state, self.dt
        kick(state.velocities, state.angular_velocities, state.forces, state.torques, state.inverse_mass,
             state.inverse_inertia, self.gravity, 0.5 * dt)
        largest_displacement_squared = drift(state.positions, state.velocities, dt, state.positions_at_build)
        self.walls.move(dt)
        for contributor in self.contributors:
            contributor.move(dt)
        if 4.0 * largest_displacement_squared > self.skin * self.skin:
            self._rebuild()
        self._compute_forces()
        kick(state.velocities, state.angular_velocities, state.forces, state.torques, state.inverse_mass,
             state.inverse_inertia, self.gravity, 0.5 * dt)
        # Work done on the particles by moving walls: -F_wall . v_wall dt.
        self.walls.work -= float(np.sum(self.walls.forces * self.walls.velocities)) * dt

    def _rebuild(self) -> None:
        if self.comm.size > 1 and self.neighbors.builds > 0:
            self._share_history()
        self.neighbors.rebuild(self.state, self.skin)

    def _share_history(self) -> None:
        """Make every rank's copy of the contact history complete before a rebuild.

        Each rank updated only the rows (and particles' wall springs) it owns;
        the others are zeroed here and the copies summed.
        """
        first, last = self.owned_range()
        history = self.neighbors.history
        row_first, row_last = self.neighbors.offsets[first], self.neighbors.offsets[last]
        history[:row_first] = 0.0
        history[row_last:] = 0.0
        self.comm.Allreduce(MPI.IN_PLACE, history, op=MPI.SUM)
        for per_particle in (self.state.wall_history, *self.state.fields.values()):
            per_particle[:first] = 0
            per_particle[last:] = 0
            self.comm.Allreduce(MPI.IN_PLACE, per_particle, op=MPI.SUM)

    def _compute_forces(self) -> None:
        state, tables, walls, neighbors = self.state, self.tables, self.walls, self.neighbors
        state.forces[:] = 0.0
        state.torques[:] = 0.0
        walls.forces[:] = 0.0
        first, last = self.owned_range()
        rolling = tables.rolling_enabled
        elastic, dissipated, contacts = pair_forces(
            first, last, neighbors.offsets, neighbors.partners, neighbors.history,
            state.positions, state.velocities, state.angular_velocities, state.radii, state.mass,
            state.inverse_inertia, state.material_index,
            tables.effective_modulus, tables.effective_shear_modulus, tables.damping_coefficient,
            tables.friction, tables.rolling_friction, tables.model_code, tables.normal_stiffness,
            tables.tangential_ratio, tables.characteristic_speed, self.dt, rolling,
            state.forces, state.torques)
        if walls.count:
            wall_elastic, wall_dissipated, wall_contacts = plane_wall_forces(
                first, last, walls.points, walls.normals, walls.velocities, walls.material_index,
                state.wall_history, state.positions, state.velocities, state.angular_velocities, state.radii,
                state.mass, state.inverse_inertia, state.material_index,
                tables.effective_modulus, tables.effective_shear_modulus, tables.damping_coefficient,
                tables.friction, tables.rolling_friction, tables.model_code, tables.normal_stiffness,
                tables.tangential_ratio, tables.characteristic_speed, self.dt, rolling,
                state.forces, state.torques, walls.forces)
            elastic += wall_elastic
            dissipated += wall_dissipated
            contacts += wall_contacts
        for contributor in self.contributors:
            extra_elastic, extra_dissipated, extra_contacts = contributor.add_forces(self, first, last)
            elastic += extra_elastic
            dissipated += extra_dissipated
            contacts += extra_contacts
        if self.comm.size > 1:
            for contributor in self.contributors:
                contributor.reduce(self.comm)
            self.comm.Allreduce(MPI.IN_PLACE, state.forces, op=MPI.SUM)
            self.comm.Allreduce(MPI.IN_PLACE, state.torques, op=MPI.SUM)
            if walls.count:
                self.comm.Allreduce(MPI.IN_PLACE, walls.forces, op=MPI.SUM)
            scalars = np.array([elastic, dissipated, contacts], dtype=float)
            self.comm.Allreduce(MPI.IN_PLACE, scalars, op=MPI.SUM)
            elastic, dissipated, contacts = scalars[0], scalars[1], int(round(scalars[2]))
        self.elastic_energy = float(elastic)
        self.dissipated_energy += float(dissipated)
        self.contact_count = int(contacts)

    # ---------------------------------------------------------------- energies
    def energies(self) -> dict:
        state = self.state
        kinetic = 0.5 * float(np.sum(state.mass * np.einsum("ij,ij->i", state.velocities, state.velocities)))
        inertia = 1.0 / state.inverse_inertia
        rotational = 0.5 * float(np.sum(inertia * np.einsum("ij,ij->i", state.angular_velocities,
                                                             state.angular_velocities)))
        potential = -float(np.sum(state.mass * (state.positions @ self.gravity)))
        return {
            "kinetic_energy": kinetic,
            "rotational_energy": rotational,
            "potential_energy": potential,
            "elastic_energy": self.elastic_energy,
            "dissipated_energy": self.dissipated_energy,
            "wall_work": self.walls.work,
        }

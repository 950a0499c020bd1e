"""The clumps of a particle system: body arrays, their step, their loads, energies and checkpoint.

The member spheres of every clump are ordinary rows of the ParticleState (the contact code sees
spheres).  Two per-particle fields tie them to their body:

    clump_body    int64, the body's global id (-1: a single sphere); sent to ghosts (the neighbour
                  list leaves out the pairs of one body, pdemfem.neighbors.verlet)
    clump_offset  (3,) the member's centre relative to the body's centre of mass, body principal frame

A member's row carries its mass share (pdemfem.clumps.template) as its mass and 2/5 share r^2 as
its inertia, which the contact laws read; the sphere integrator skips members.  One step
(ParticleSystem.step with clumps):

    first_half    free spheres, if any: half kick and drift (kick_drift_free_spheres, which zeroes every
                  owned row's loads, as kick_drift does); bodies and their members in one kernel
                  (first_half_bodies): half kick, drift, R(q), omega from L (the rotation vectorised over
                  the bodies), then the member rows in row order (position, velocity, spin; the lever R(q)
                  offset kept per row; the loads zeroed)
    (list rebuild or ghost update; every contact force on the rows)
    sum_loads     body F, T <- the owned members' loads, in row order (sum_body_loads)
    second_half   free spheres, if any: half kick; bodies: half kick and omega (with the R of the first half),
                  then their members' velocities and spins, in row order (second_half_bodies); or, with
                  defer_second_half, the bodies' part is left pending (below)

Deferred load sum and second half (defer_second_half, set by the Simulation when no solid is coupled):
nothing in a step reads the bodies' loads, their kicked velocities, their omega or their members'
velocities and spins before the next step's first_half overwrites them (it recomputes omega and places
the members again; the contacts come after it).  So sum_loads and second_half only note their work as
pending, and the next first_half_bodies sums the member rows' loads (they keep them until it zeroes them)
and does the bodies' kick just before its own half kick, on the same loads (the same roundings, bit for
bit: one pass over the bodies instead of two kernel calls, and no omega or member pass).  Whoever reads
the state between steps first calls finish_second_half (ParticleSystem.finish_clump_step), which runs
the pending sum_body_loads and second_half_bodies: Simulation.step before it returns, a stream's
insertion before it changes the rows.  The readers of the body state (energy_sums, state_dict, a
rebuild's remove_leaving) refuse a pending kick.

The body kernels reach a member's body through the index refresh_rows makes at a list rebuild
(row_body: the local index of each owned row's body, -1 for a free sphere), and only when the rows
hold other particles than at the last one.

The kick formulas are those of pdemfem.particles.integrate, so a clump of one sphere follows the
sphere's translation bit for bit (its rotation goes through L = I omega: equal to round-off).

Ranks: a body belongs to the rank whose box holds its centre of mass, and so do all its members
(owned rows there, wherever they stick out); at a list rebuild the members migrate to their body's
owner (`member_destinations`) and the bodies follow (`migrate_bodies`).  Members reach the other
ranks as ghosts by position like any particle; the ghost cutoff is widened by twice the largest
member offset (a member sticks out of its owner's box by at most that, and so may its partner).
After the insertion and after a checkpoint is read every rank holds every body (`replicated`);
the next rebuild keeps each rank's own.  Body arrays are kept in id order.
"""
from __future__ import annotations

import numpy as np
from mpi4py import MPI
from numba import njit

from pdemfem import state_dict as kinds
from pdemfem.clumps.quaternion import quaternion_conjugates, quaternion_products
from pdemfem.clumps.rigid_body import (ROTATION_ROWS, angular_momenta_from_velocities,
                                       angular_velocities_from_momenta, body_rotations, first_half_bodies,
                                       index_members, rotation_constants, rotational_energies,
                                       second_half_bodies, sum_body_loads)
from pdemfem.particles.energy import particle_energy_sums
from pdemfem.particles.integrate import keep_largest, kick_drift_row

BODY_FIELD = "clump_body"
OFFSET_FIELD = "clump_offset"


@njit(cache=True)
def kick_drift_free_spheres(owned_count, body, positions, velocities, angular_velocities, forces, torques,
                            inverse_mass, inverse_inertia, gravity, half_dt, dt, positions_at_build):
    """pdemfem.particles.integrate.kick_drift over the rows that are not clump members (the same arithmetic,
    the same largest squared displacement; their loads zeroed for the next force evaluation).  The
    members' rows are left to first_half_bodies, which may have to sum their loads onto the bodies first
    (a deferred load sum) and zeroes them."""
    largest = 0.0
    for i in range(owned_count):
        if body[i] >= 0:
            continue
        largest = keep_largest(largest, kick_drift_row(i, positions, velocities, angular_velocities, forces, torques,
                                                       inverse_mass, inverse_inertia, gravity, half_dt, dt,
                                                       positions_at_build))
    return largest


@njit(cache=True)
def kick_free_spheres(owned_count, body, velocities, angular_velocities, forces, torques, inverse_mass,
                      inverse_inertia, gravity, half_dt):
    """pdemfem.particles.integrate.kick over the rows that are not clump members."""
    for i in range(owned_count):
        if body[i] >= 0:
            continue
        for axis in range(3):
            velocities[i, axis] += half_dt * (forces[i, axis] * inverse_mass[i] + gravity[axis])
            angular_velocities[i, axis] += half_dt * torques[i, axis] * inverse_inertia[i]


class ClumpBodies(kinds.StateComponent):
    """The rigid bodies (arrays over bodies, world frame; see the module docstring)."""

    def __init__(self, ids, group_index, positions, orientations, velocities, angular_velocities, masses,
                 principal_moments, principal_orientations):
        self.ids = np.ascontiguousarray(ids, dtype=np.int64)
        self.group_index = np.ascontiguousarray(group_index, dtype=np.int32)
        self.positions = np.ascontiguousarray(positions, dtype=np.float64).reshape(-1, 3)
        self.orientations = np.ascontiguousarray(orientations, dtype=np.float64).reshape(-1, 4)
        self.velocities = np.ascontiguousarray(velocities, dtype=np.float64).reshape(-1, 3)
        self.masses = np.ascontiguousarray(masses, dtype=np.float64)
        self.principal_moments = np.ascontiguousarray(principal_moments, dtype=np.float64).reshape(-1, 3)
        # Body principal frame -> the clump frame the scene gave (reported orientations are the clump frame's).
        self.principal_orientations = np.ascontiguousarray(principal_orientations, dtype=np.float64).reshape(-1, 4)
        self.angular_momenta = np.zeros((self.count, 3))
        angular_momenta_from_velocities(self.count, self.orientations,
                                        np.ascontiguousarray(angular_velocities, dtype=np.float64).reshape(-1, 3),
                                        self.principal_moments, self.angular_momenta)
        self.forces = np.zeros((self.count, 3))
        self.torques = np.zeros((self.count, 3))
        self.lost = 0  # bodies removed on this rank (a member left domain.box)
        # Every rank holds every body (after the insertion or a checkpoint read) until the next rebuild.
        self.replicated = True
        self.comm = None  # set by the particle system
        # Leave the load sum and the bodies' second half to the next first_half (module docstring); set by the
        # Simulation.
        self.defer_second_half = False
        self._pending_half_dt = 0.0  # dt/2 of the pending second half kick (0.0: none; its load sum pends too)
        self._pending_gravity = None
        self._derive()

    @classmethod
    def from_insertion(cls, inserted):
        """Bodies of pdemfem.particles.insert.InsertedClumps (ids 0..B-1 in insertion order)."""
        templates = [inserted.templates[int(group)] for group in inserted.group_index]
        return cls(np.arange(len(inserted.group_index)), inserted.group_index, inserted.positions,
                   inserted.orientations, inserted.velocities, inserted.angular_velocities,
                   [t.mass for t in templates], [t.principal_moments for t in templates],
                   [t.principal_orientation for t in templates])

    def _derive(self):
        """The arrays that follow from the stored ones (after every reorder, removal or load)."""
        self.inverse_masses = 1.0 / self.masses
        # R(q) of every body: set by each step's drift, read by the members' placement, the load sum
        # and the second half's omega.
        self.rotations = np.empty((self.count, 3, 3))
        body_rotations(self.count, self.orientations, self.rotations)
        self.angular_velocities = np.zeros((self.count, 3))
        angular_velocities_from_momenta(self.count, self.orientations, self.angular_momenta, self.principal_moments,
                                        self.angular_velocities)
        # Columns of the drift's vectorised rotation (first_half_bodies), kept from step to step: scratch
        # rows, and the rows of rotation_constants, filled for the dt of the first step.
        self._rotation_work = np.empty((ROTATION_ROWS, self.count))
        self._rotation_dt = None
        # No member index until refresh_rows (the next rebuild) makes one for these bodies.
        self.row_body = np.zeros(0, dtype=np.int64)
        self.row_levers = np.zeros((0, 3))
        self.member_count = 0
        self._indexed = None

    @property
    def count(self) -> int:
        return len(self.ids)

    # ------------------------------------------------------------------ members
    @staticmethod
    def attach(state, member_body, member_offsets, member_mass) -> None:
        """Register the member fields on `state` (rows as inserted; member_body: body ids, -1 for a
        single sphere) and give members their mass shares."""
        body = state.add_field(BODY_FIELD, (), np.int64, fill=-1, ghost_rebuild=True)
        body[:] = member_body
        state.add_field(OFFSET_FIELD, (3,))[:] = member_offsets
        members = body >= 0
        state.mass[members] = member_mass[members]
        state.inverse_mass[members] = 1.0 / state.mass[members]
        state.inverse_inertia[members] = 1.0 / (0.4 * state.mass[members] * state.radii[members] ** 2)

    def local_index(self, body_ids) -> np.ndarray:
        """Index in these (id-sorted) arrays of bodies by id; every id must be held here."""
        index = np.searchsorted(self.ids, body_ids)
        if len(body_ids) and (index.max() >= self.count or np.any(self.ids[index] != body_ids)):
            raise RuntimeError("a clump member's body is not on its rank")
        return index.astype(np.int64)

    @staticmethod
    def protrusion(state, comm) -> float:
        """Largest distance of a member centre from its body's centre of mass (over the ranks)."""
        offsets = state.fields[OFFSET_FIELD][:state.owned_count]
        local = float(np.sqrt((offsets ** 2).sum(axis=1).max())) if len(offsets) else 0.0
        return comm.allreduce(local, op=MPI.MAX) if comm.size > 1 else local

    def _refuse_pending_kick(self, reader: str) -> None:
        if self._pending_half_dt:
            raise RuntimeError(f"clumps: {reader} with the second half kick pending (call "
                               f"ParticleSystem.finish_clump_step first)")

    def member_destinations(self, state, destinations, decomposition) -> np.ndarray:
        """Rank of every owned row at a rebuild: a member goes to its body's owner."""
        body = state.fields[BODY_FIELD][:state.owned_count]
        members = np.flatnonzero(body >= 0)
        if len(members):
            destinations = destinations.copy()
            centres = self.positions[self.local_index(body[members])]
            destinations[members] = decomposition.owners(centres)
        return destinations

    _ARRAYS = ("ids", "group_index", "positions", "orientations", "velocities", "masses", "principal_moments",
               "principal_orientations", "angular_momenta", "forces", "torques")

    def _keep(self, rows) -> None:
        for name in self._ARRAYS:
            setattr(self, name, np.ascontiguousarray(getattr(self, name)[rows]))

    def _sort(self) -> None:
        self._keep(np.argsort(self.ids, kind="stable"))
        self._derive()

    def migrate_bodies(self, comm, decomposition) -> None:
        """Collective, at a rebuild after the members moved: every body to the rank owning its centre."""
        owners = decomposition.owners(self.positions) if self.count else np.zeros(0, dtype=np.int64)
        if self.replicated:  # every rank holds them all: keep one's own
            self._keep(np.flatnonzero(owners == comm.rank))
            self.replicated = False
            self._sort()
            return
        outgoing = [None] * comm.size
        for rank in range(comm.size):
            if rank != comm.rank:
                rows = np.flatnonzero(owners == rank)
                outgoing[rank] = {name: getattr(self, name)[rows] for name in self._ARRAYS} if len(rows) else None
        incoming = comm.alltoall(outgoing)
        self._keep(np.flatnonzero(owners == comm.rank))
        for received in incoming:
            if received is not None:
                for name in self._ARRAYS:
                    setattr(self, name, np.concatenate([getattr(self, name), received[name]]))
        self._sort()

    def refresh_rows(self, state) -> None:
        """After a rebuild (rows sorted, removed, appended): the body of each owned row (row_body, local
        index, -1 for a free sphere), the member count and the members' levers.  When the owned rows hold
        the same particles as at the last refresh and the bodies are the same (a rebuild that moved no
        row: one rank, no reorder), the index stands as it is: the levers were set by this step's
        first_half and the rows have not moved since."""
        self.replicated = False
        owned = state.owned_count
        row_ids = state.ids[:owned]
        if (self._indexed is not None and self._indexed[1] is self.ids and len(self._indexed[0]) == owned
                and np.array_equal(self._indexed[0], row_ids)):
            return
        body = state.fields[BODY_FIELD][:owned]
        row_body = np.empty(owned, dtype=np.int64)
        levers = np.zeros((owned, 3))  # (a free sphere's row stays 0: never read)
        # Levers R(q) offset: the load sum reads them before the next step places the members.
        members = index_members(owned, body, state.fields[OFFSET_FIELD], self.ids, self.rotations, row_body, levers)
        if members < 0:
            raise RuntimeError(f"the body {int(body[-1 - members])} of a clump member is not on its rank")
        self.row_body, self.row_levers, self.member_count = row_body, levers, members
        self._indexed = (row_ids.copy(), self.ids)

    # ------------------------------------------------------------------ the step
    def first_half(self, state, gravity, dt) -> float:
        """Half kick and drift of the free spheres and the bodies (zeroing the owned rows' loads, as
        kick_drift does); members follow their bodies.  Returns the largest squared displacement of a
        row since the list build."""
        largest = 0.0
        pending_half_dt = self._pending_half_dt
        if pending_half_dt and gravity is not self._pending_gravity:  # (the system's gravity: never so)
            self.finish_second_half(state)
            pending_half_dt = 0.0
        self._pending_half_dt = 0.0
        if self.member_count < state.owned_count:  # some owned rows are free spheres
            largest = kick_drift_free_spheres(state.owned_count, state.fields[BODY_FIELD], state.positions,
                                              state.velocities, state.angular_velocities, state.forces,
                                              state.torques, state.inverse_mass, state.inverse_inertia, gravity,
                                              0.5 * dt, dt, state.positions_at_build)
        if dt != self._rotation_dt:
            rotation_constants(self.count, self.principal_moments, dt, self._rotation_work)
            self._rotation_dt = dt
        members = first_half_bodies(self.count, self.positions, self.velocities, self.orientations,
                                    self.angular_momenta, self.forces, self.torques, self.inverse_masses,
                                    self.principal_moments, gravity, pending_half_dt, 0.5 * dt, dt, self.rotations,
                                    self.angular_velocities, self._rotation_work, len(self.row_body), self.row_body,
                                    state.fields[OFFSET_FIELD], self.row_levers, state.positions, state.velocities,
                                    state.angular_velocities, state.positions_at_build, state.forces, state.torques)
        return max(largest, members)

    def sum_loads(self, state) -> None:
        """Body force and torque about the centre of mass from the owned members' contact loads; with
        defer_second_half left pending with the second half (module docstring)."""
        if self.defer_second_half:  # (second_half leaves it pending with the kick)
            return
        sum_body_loads(self.count, len(self.row_body), self.row_body, self.row_levers, state.forces,
                       state.torques, self.forces, self.torques)

    def second_half(self, state, gravity, dt) -> None:
        """Half kick of the free spheres; the bodies' half kick, omega and members' motion, or with
        defer_second_half the bodies' part left pending for the next first_half (module docstring)."""
        if self.member_count < state.owned_count:  # some owned rows are free spheres
            kick_free_spheres(state.owned_count, state.fields[BODY_FIELD], state.velocities,
                              state.angular_velocities, state.forces, state.torques, state.inverse_mass,
                              state.inverse_inertia, gravity, 0.5 * dt)
        if self.defer_second_half:  # (sum_loads left the load sum to the same next first_half)
            self._pending_half_dt = 0.5 * dt
            self._pending_gravity = gravity
            return
        self._second_half_bodies(state, gravity, 0.5 * dt)

    def finish_second_half(self, state) -> None:
        """The pending load sum and second half of the bodies, if any: their loads, kick, omega and members'
        velocities and spins, as sum_loads and second_half would have done them (the state every reader
        between steps expects)."""
        if self._pending_half_dt:
            half_dt, self._pending_half_dt = self._pending_half_dt, 0.0
            sum_body_loads(self.count, len(self.row_body), self.row_body, self.row_levers, state.forces,
                           state.torques, self.forces, self.torques)
            self._second_half_bodies(state, self._pending_gravity, half_dt)

    def _second_half_bodies(self, state, gravity, half_dt) -> None:
        second_half_bodies(self.count, self.velocities, self.angular_momenta, self.forces, self.torques,
                           self.inverse_masses, gravity, half_dt, self.rotations, self.principal_moments,
                           self.angular_velocities, len(self.row_body), self.row_body, self.row_levers,
                           state.velocities, state.angular_velocities)

    # ------------------------------------------------------------------ energies
    def energy_sums(self, state, gravity):
        """(kinetic, rotational, potential, largest squared speed) of the free spheres and the bodies."""
        self._refuse_pending_kick("energies")
        kinetic, rotational, potential, fastest = particle_energy_sums(
            state.owned_count, state.mass, state.velocities, state.angular_velocities, state.inverse_inertia,
            state.positions, gravity, state.fields[BODY_FIELD])
        spins = np.zeros(self.count)
        rotational_energies(self.count, self.orientations, self.angular_momenta, self.principal_moments, spins)
        kinetic += 0.5 * float(np.sum(self.masses * np.einsum("ij,ij->i", self.velocities, self.velocities)))
        rotational += float(spins.sum())
        potential -= float(np.sum(self.masses * (self.positions @ gravity)))
        return kinetic, rotational, potential, fastest

    def clump_frame_orientations(self) -> np.ndarray:
        """(B, 4) orientations clump frame -> world (the frame the scene's spheres are given in)."""
        return quaternion_products(self.orientations, quaternion_conjugates(self.principal_orientations))

    # ------------------------------------------------------------------ removal
    def remove_leaving(self, state, outside: np.ndarray, gravity, half_dt: float) -> tuple:
        """(`outside` (owned rows leaving) grown to every member of a body one of whose members leaves, the ids of
        those bodies, the kinetic + rotational + potential energy [J] each carries out); those bodies are dropped
        and the remaining members' body indices renumbered.  The energy is the end of the step's, as
        pdemfem.particles.energy.energy_leaving books a sphere's: the rebuild comes at the half step, and the
        second half kick is completed with gravity (the step's contact loads are not known yet).  The caller
        counts the bodies (ClumpBodies.lost) and books their energy once: while the bodies are `replicated`
        (after a checkpoint was read), ranks holding members of one body each report it."""
        self._refuse_pending_kick("a list rebuild")  # (every rebuild passes here first)
        body = state.fields[BODY_FIELD][:state.owned_count]
        leaving = np.unique(body[outside & (body >= 0)])
        if not len(leaving):
            return outside, np.zeros(0, dtype=np.int64), np.zeros(0)
        outside = outside | np.isin(body, leaving)
        gone = np.isin(self.ids, leaving)
        rows = np.flatnonzero(gone)
        spins = np.zeros(len(rows))
        gravity = np.asarray(gravity, dtype=float)
        velocities = self.velocities[rows] + half_dt * gravity
        rotational_energies(len(rows), np.ascontiguousarray(self.orientations[rows]),
                            np.ascontiguousarray(self.angular_momenta[rows]),
                            np.ascontiguousarray(self.principal_moments[rows]), spins)
        energies = (0.5 * self.masses[rows] * np.einsum("ij,ij->i", velocities, velocities)
                    + spins - self.masses[rows] * (self.positions[rows] @ gravity))
        ids = self.ids[rows].copy()
        self._keep(np.flatnonzero(~gone))
        self._derive()
        return outside, ids, energies

    # ------------------------------------------------------------------ checkpoints
    _STORED = ("ids", "group_index", "positions", "orientations", "velocities", "angular_momenta", "masses",
               "principal_moments", "principal_orientations", "forces", "torques")

    def state_dict(self) -> dict:
        """Collective: the bodies' arrays as a table keyed by the rank of each id among all bodies
        (the file does not depend on the rank count), and the count of lost bodies."""
        self._refuse_pending_kick("a checkpoint")
        comm = self.comm
        if comm is not None and comm.size > 1:
            every = np.sort(np.concatenate(comm.allgather(self.ids)))
            lost = comm.allreduce(int(self.lost))
        else:
            every, lost = self.ids, int(self.lost)
        keys = np.searchsorted(every, self.ids)
        result = {name: kinds.keyed_slab(getattr(self, name), keys) for name in self._STORED}
        result["lost"] = kinds.scalar(lost)
        return result

    def load_state_dict(self, stored: dict) -> None:
        missing = [name for name in self._STORED if name not in stored]
        if missing:
            raise kinds.StateMismatch(f"lacks the clump state {missing} (written by a scene without clumps)")
        for name in self._STORED:
            current = getattr(self, name)
            values = np.asarray(stored[name], dtype=current.dtype)
            setattr(self, name, np.ascontiguousarray(values.reshape((-1, *current.shape[1:]))))
        # The total is counted once, on rank 0.
        self.lost = int(stored["lost"]) if self.comm is None or self.comm.rank == 0 else 0
        self.replicated = True
        self._pending_half_dt = 0.0  # the stored bodies' loads are summed and their state kicked
        self._sort()


@njit(cache=True)
def drop_same_body_pairs(row_particles, offsets, partners, body):
    """Remove the listed pairs of two members of one clump from a CSR list, in place (order kept);
    returns the new pair count (offsets are rewritten)."""
    written = 0
    start = offsets[0]
    for row in range(row_particles.shape[0]):
        end = offsets[row + 1]
        own = body[row_particles[row]]
        offsets[row] = written
        for k in range(start, end):
            j = partners[k]
            if own >= 0 and body[j] == own:
                continue
            partners[written] = j
            written += 1
        start = end
    offsets[row_particles.shape[0]] = written
    return written

"""A solid's contact surface mirrored into the DEM as a moving triangle surface.

The triangles are the solid's contact-group faces (P2 faces split into four);
their vertices are the FE surface nodes, refreshed from the solid's
displacement and velocity after every FE step.  Contact counter-forces go back
to the owning FE nodes through Solid.add_nodal_forces (PETSc ADD_VALUES), so
every rank adds only the contacts of the particles it owns and each contact is
summed exactly once.

With heat on and a conducting solid, the surface vertices carry the solid's nodal temperatures
(refreshed after every FE advance) and the contacts' heat [J], spread onto the vertices by the
contact point's weights (pdemfem.walls.triangle_contact), is summed over the steps of the window and
given to the solid as a constant nodal heat flow over the next advance (Solid.add_nodal_heat): the
heat the particles lose is what the solid's nodes receive, to round-off.

The contacts' dashpots are not part of that held load: the solid applies them to its
surface nodes at every FE sub-step and the particles get the balancing impulse after the
advance (pdemfem.coupling.dampers explains why and how momentum stays exact).

A solid with a prescribed rigid motion (fem/frame.py) is mirrored in world axes.  Each advance's
surface displacement splits into the frame's part and the elastic part R(T) du (R(T) the frame's
orientation when the window's forces were turned into it): the particles' forces times minus the frame
part is the work the frame fed in (`frame_work_local`, booked like a moving wall's), the elastic part
is the solid's own business.  The dashpot records and their balance use velocities relative to the
frame's material, as the conveyor's use the belt's.

Partial gather (pdemfem.coupling.selection).  On several ranks, in a simulation without streams, a
surface without motion refreshes after each advance only the nodes of the triangles near the rank's own
particles (one PETSc scatter of those nodes); the others keep the positions of the selection's time,
and no particle can reach them (selection.py gives the bound).  A rank selects anew, together with all
others, when its particles leave the region the selection was made for (checked at each list build:
one reduction) or the surface has drifted more than a quarter margin (measured after each advance on
the nodes each rank owns; a flag in the next DEM step's one SUM, the new selection at the next advance).
The whole surface is brought back (every rank, collective) whenever all of it is needed: a new selection,
a checkpoint (the surface's vertices are written as one array for all ranks), `refresh_vertices()`
without an interval.  Nothing else reads the left-out vertices: contacts, their dashpot records,
heat and the blended gap involve only the triangles a particle touches.  Moving-frame solids and
scenes with streams (whose insertion tests every triangle on every rank) keep the whole gather.
"""
from __future__ import annotations

import numpy as np

from mpi4py import MPI

from pdemfem import state_dict as kinds
from pdemfem.coupling import selection as chosen
from pdemfem.coupling.dampers import (RECORD_COLUMNS, RECORD_DAMPING, RECORD_ID, RECORD_INDEX, RECORD_TRIANGLE,
                                      RECORD_WEIGHTS, SHARE_COLUMNS, balance_particles, balance_share_springs,
                                      make_records, make_share_rows, node_dampers, node_share_springs)
from pdemfem.coupling.transfer import spread_linear
from pdemfem.parallel.exchange import allgather_rows
from pdemfem.walls.mesh import TriangleSurface


class SolidTriangleSurface(TriangleSurface):
    """A solid's mirrored TriangleSurface: before each force evaluation its CoupledSurface may renew the
    partial gather's selection (every rank calls add_forces for every contributor at every step)."""

    def __init__(self, *args, before_contacts=None, **options):
        super().__init__(*args, **options)
        self.before_contacts = before_contacts
        # The partial gather's drift flag rides the step's one SUM over the ranks (local_totals) when carried.
        self.carry_flag = False
        self.flag = 0.0
        self.summed_flag = 0.0

    def add_forces(self, system, first: int, last: int):
        if self.before_contacts is not None:
            self.before_contacts(system)
        return super().add_forces(system, first, last)

    def local_totals(self) -> np.ndarray:
        totals = super().local_totals()
        return np.append(totals, self.flag) if self.carry_flag else totals

    def take_summed_totals(self, summed: np.ndarray) -> None:
        if self.carry_flag:
            self.summed_flag = float(summed[-1])
            summed = summed[:-1]
        super().take_summed_totals(summed)

    def mark_vertices_moved(self) -> None:
        """Some vertices were written in place (set_vertices' bookkeeping without the copy)."""
        self._bvh_current = False
        self._vertices_moved = True


class CoupledSurface(kinds.StateComponent):
    # Tests switch the partial gather off to compare with the whole one.
    partial_gather = True

    def __init__(self, solid, material_index: int, smooth_angle: float = 1.0, skin=None, blended: bool = False):
        self.solid = solid
        self.name = solid.name
        contact = solid.contact_surface()
        self.node_indices = contact.node_indices              # global FE node numbers of the surface nodes
        self.triangles = np.ascontiguousarray(contact.triangles, dtype=np.int64)  # into node_indices
        _, positions, velocities = solid.surface_state()
        self.triangle_surface = SolidTriangleSurface(self.name, positions, self.triangles, material_index,
                                                     velocities=velocities, smooth_angle=smooth_angle, skin=skin,
                                                     blended=blended, work_of_transport_only=True,
                                                     transport_velocity=solid.config.transport_velocity,
                                                     before_contacts=self._before_contacts)
        # Partial gather (module docstring): off until the simulation allows it.
        self._partial = False
        self.selection = None          # selection.SurfaceSelection; None: the whole surface is gathered
        self.selections = 0            # how many were made (tests, benchmarks)
        self._stale = False            # some vertices hold an older state than the solid's (partial refreshes)
        self._seen_build = None        # the particles' positions_at_build array of the last list build seen
        self._region = None
        self._reach = 0.0
        self._margin = 0.0
        self._last_interval = None
        self._displacement_before = None
        self._positions_before = None
        self.node_forces = np.zeros((len(self.node_indices), 3))
        # Forces summed over the DEM steps since the last FE advance (sub-cycling).
        self.accumulated_forces = np.zeros_like(self.node_forces)
        # This rank's contact dashpots of the DEM steps since the last advance (dampers.RECORD_COLUMNS rows),
        # and those of the advance in progress (balanced on the particles after it).
        self.damper_records = []
        self._advanced_records = np.zeros((0, RECORD_COLUMNS))
        self._advanced_spring_scale = 1.0  # the records' share of the advance (send_forces_to_solid's scale)
        # The blended contacts' normal springs (dampers.py, share rows) of the steps since the last advance, kept,
        # checkpointed and moved between ranks like the records, and those of the advance in progress.
        self.share_rows = []
        self._advanced_shares = np.zeros((0, SHARE_COLUMNS))
        self.particle_system = None  # set by the simulation: the dashpot balance acts on its particles
        self.dissipation_correction_local = 0.0  # [J], this rank's contacts (dampers.balance_particles)
        # Heat: only when the solid conducts (Solid.heat); the particles' side decides whether contacts conduct.
        self.conducting = getattr(solid, "heat", None) is not None
        self.frame = getattr(solid, "frame", None)
        if self.frame is not None:
            self.frame_work_local = 0.0  # [J] this rank's contacts: work the moving frame did on the particles
            # The frame's part of the last advance's surface displacement (per vertex), and the mean force of the
            # window before it (this rank's contacts): its work is booked when the next window's force is known.
            self._pending_frame_part = np.zeros((len(self.node_indices), 3))
            self._pending_forces = None
            self.refresh_vertices()
        if self.conducting:
            self.triangle_surface.vertex_heat = np.zeros(len(self.node_indices))
            self.refresh_temperatures()

    def collect_contact_forces(self, keep_dampers: bool = True) -> None:
        """Add this step's contact counter-forces (this rank's contacts) to the accumulator and keep the
        contacts' dashpots for the next advance."""
        contacts = self.triangle_surface.contacts
        if keep_dampers and self.particle_system is not None and len(contacts.triangle):
            records = make_records(contacts.particle, self.particle_system.state.ids[contacts.particle],
                                   contacts.triangle, contacts.weights, contacts.damping)
            if len(records) and np.any(self.triangle_surface.transport_velocity):
                self._remove_transport(records)
            if len(records):
                self.damper_records.append(records)
            if len(contacts.share_contact):
                # ids per contact, as make_records takes them (the rows are indexed by the contact's record).
                self.share_rows.append(make_share_rows(contacts.particle,
                                                       self.particle_system.state.ids[contacts.particle],
                                                       contacts.share_contact, contacts.share_vertex,
                                                       contacts.share_value, contacts.damping))
        self.node_forces[:] = 0.0
        if len(contacts.triangle):
            # P2 faces too: by the flat sub-triangle's weights, the gap's own derivative (transfer.py).
            spread_linear(self.triangles, contacts.triangle, contacts.weights, contacts.force, self.node_forces)
        if self.triangle_surface.blended:
            # The contacts' normal elastic forces, spread over the nodes under the particle by the blended gap.
            self.node_forces += self.triangle_surface.vertex_forces
        self.accumulated_forces += self.node_forces

    def _remove_transport(self, records) -> None:
        """Conveyor: express the records' particle and surface velocities relative to the moving belt
        material (minus the transport velocity's tangential part at each contact), so the solid's nodal
        dashpots act on C (u_p - T_t - v_k) and the particles' balance (dampers.py) stays exact."""
        transport = self.triangle_surface.transport_velocity
        normals = records[:, RECORD_DAMPING + 2:RECORD_DAMPING + 5]
        tangential = transport - (normals @ transport)[:, None] * normals
        records[:, RECORD_DAMPING + 6:RECORD_DAMPING + 9] -= tangential
        records[:, RECORD_DAMPING + 9:RECORD_DAMPING + 12] -= tangential

    def _remove_frame_velocity(self, records, interval: float) -> None:
        """Moving frame, before an advance of `interval`: the records' particle and surface velocities relative
        to the frame's material at the contact point as the frame will move over that advance (its chord
        velocity, interpolated by the contact's weights), so the nodal dashpots act on the elastic velocity the
        solid integrates and the particles' balance after the advance sees the same frame motion."""
        solid = self.solid
        coming = (self.frame.chord_velocities(self._body_positions, solid.time, interval)
                  if interval > 0.0 else self._frame_vertex_velocities)
        triangles = records[:, RECORD_TRIANGLE].astype(np.int64)
        weights = records[:, RECORD_WEIGHTS:RECORD_WEIGHTS + 3]
        frame = np.einsum("nk,nkd->nd", weights, coming[self.triangles[triangles]])
        records[:, RECORD_DAMPING + 6:RECORD_DAMPING + 9] -= frame
        records[:, RECORD_DAMPING + 9:RECORD_DAMPING + 12] -= frame

    def send_forces_to_solid(self, scale: float, dampers: bool = True, interval: float = 0.0, steps: int = 1,
                             springs: bool = False) -> None:
        """Add scale x the accumulated forces to the solid's nodal loads (ADD_VALUES to the owners).

        dampers: the kept contacts' dashpots go to the solid as nodal dashpots (scaled alike) and leave
        the held load; without, the held load keeps them (the prime, whose impulse is F^0 dt exactly).
        A moving frame (interval: the coming advance's, steps: the window's DEM steps) books the work of the
        last advance's frame displacement now that the force after it is known (_book_frame_work).  The contact
        springs over the FE sub-steps act on an advance of one DEM step, and on a longer one with `springs`."""
        forces = scale * self.accumulated_forces
        if self.frame is not None:
            self._book_frame_work(self.accumulated_forces / steps)
        records = np.concatenate(self.damper_records) if self.damper_records else np.zeros((0, RECORD_COLUMNS))
        self.damper_records = []
        with_springs = dampers and self.frame is None and (steps == 1 or springs)
        shares = (np.concatenate(self.share_rows) if self.share_rows and with_springs
                  else np.zeros((0, SHARE_COLUMNS)))
        self.share_rows = []
        if dampers and len(records) and self.frame is not None:
            self._remove_frame_velocity(records, interval)
        self._advanced_records = records if dampers else records[:0]
        self._advanced_shares = shares
        self._advanced_spring_scale = scale
        if dampers and (len(records) or len(shares)):
            tensors = np.zeros((len(self.node_indices), 6))
            targets = np.zeros((len(self.node_indices), 3))
            previous_forces = np.zeros((len(self.node_indices), 3))
            # The contact springs over the sub-steps (dampers.py), each record's by its share of the window; a solid
            # with motion keeps the held force alone.
            springs = np.zeros((len(self.node_indices) if with_springs else 0, 6))
            node_dampers(records, self.triangles, scale, tensors, targets, previous_forces, springs)
            if len(shares):
                node_share_springs(shares, scale, springs)
            forces -= previous_forces
            damped = np.any(tensors != 0.0, axis=1)
            if len(springs):
                damped |= np.any(springs != 0.0, axis=1)
            damped = np.flatnonzero(damped)
            self.solid.add_contact_dampers(self.node_indices[damped], tensors[damped], targets[damped],
                                           springs[damped] if len(springs) else None)
        loaded = np.flatnonzero(np.any(forces != 0.0, axis=1))
        self.solid.add_nodal_forces(self.node_indices[loaded], forces[loaded])
        self.accumulated_forces[:] = 0.0

    # ------------------------------------------------------------ heat
    def refresh_temperatures(self) -> None:
        """Collective: the solid's nodal temperatures onto the surface vertices."""
        if self.selection is not None:
            rows = self.selection.rows
            self.triangle_surface.vertex_temperatures[rows] = self.selection.gather.scalar(self.solid.temperature_vec)
            return
        surface = self.solid.contact_surface()
        self.triangle_surface.set_temperature(surface.gather_scalar(self.solid.temperature_vec))

    def send_heat_to_solid(self, interval: float) -> None:
        """The heat [J] this rank's contacts sent into the vertices since the last advance, as a nodal heat
        flow [W] held over the next advance of length `interval` (so the solid receives exactly it)."""
        if not self.conducting:
            return
        heat = self.triangle_surface.vertex_heat
        loaded = np.flatnonzero(heat != 0.0)
        self.solid.add_nodal_heat(self.node_indices[loaded], heat[loaded] / interval)
        heat[:] = 0.0

    def balance_dampers(self, dt: float, exchange: bool) -> None:
        """After an advance and refresh_vertices: give the particles the dashpot impulse the solid took
        beyond what their step gave them (dampers.py).  exchange (collective): records whose particle
        this rank no longer owns (moved within a sub-cycling window, or restored on rank 0 from a
        checkpoint) are shared with all ranks and balanced where the particle lives."""
        records = self._advanced_records
        self._advanced_records = records[:0]
        shares = self._advanced_shares
        self._advanced_shares = shares[:0]
        system = self.particle_system
        if system is None:
            return
        state = system.state
        records, local_index = self._rows_where_owned(records, RECORD_COLUMNS, system, exchange)
        spring_integrals = self._spring_integrals()
        if len(spring_integrals) and (len(shares) or exchange):
            shares, share_index = self._rows_where_owned(shares, SHARE_COLUMNS, system, exchange)
            balance_share_springs(shares, share_index, spring_integrals, self._advanced_spring_scale,
                                  state.velocities, state.mass)
        if len(records):
            vertex_velocities = (self.triangle_surface.vertex_velocities if self.frame is None
                                 else self._relative_vertex_velocities)
            self.dissipation_correction_local += balance_particles(
                records, local_index, self.triangles, vertex_velocities, dt,
                state.velocities, state.angular_velocities, state.mass, state.inverse_inertia,
                spring_integrals, self._advanced_spring_scale)

    def _rows_where_owned(self, rows, columns: int, system, exchange: bool) -> tuple:
        """(rows, the row of each one's particle among this rank's owned ones, -1 where not owned here).
        exchange (collective): rows whose particle this rank does not own are shared with all ranks and kept
        where it lives; a row no rank owns any more (its particle was lost) is dropped with the particle."""
        state = system.state
        index = self._local_index(rows, state)
        if exchange:
            shared = allgather_rows(system.comm, rows[index < 0], columns)
            if len(shared):
                rows = np.concatenate([rows[index >= 0], shared])
                index = np.concatenate([index[index >= 0], self._local_index(shared, state, by_id_only=True)])
        return rows, index

    def _spring_integrals(self) -> np.ndarray:
        """Collective (on every rank alike: the sub-step count is the solid's): per vertex, the time integral of
        its displacement since the start of the advance just done (Solid.spring_integral_vec), for the rows this
        rank mirrors; no rows when the solid took one sub-step (the integral is zero) or moves with a frame."""
        if self.frame is not None or not self.solid.springs_integrated:
            return np.zeros((0, 3))
        gather = self.selection.gather if self.selection is not None else self.solid.contact_surface().whole
        integrals = np.zeros((len(self.node_indices), 3))
        integrals[gather.rows] = gather.vector(self.solid.spring_integral_vec)
        return integrals

    @staticmethod
    def _local_index(records, state, by_id_only: bool = False) -> np.ndarray:
        """Row of each record's particle among this rank's owned particles, -1 where not owned here."""
        owned = state.owned_count
        ids = records[:, RECORD_ID].astype(np.int64)
        index = np.full(len(records), -1, dtype=np.int64)
        if not len(records):
            return index
        if not by_id_only:
            guess = records[:, RECORD_INDEX].astype(np.int64)
            inside = guess < owned
            valid = np.zeros(len(records), dtype=np.bool_)
            valid[inside] = state.ids[guess[inside]] == ids[inside]
            index[valid] = guess[valid]
            if valid.all():
                return index
        if owned == 0:
            return index
        missing = np.flatnonzero(index < 0)
        order = np.argsort(state.ids[:owned], kind="stable")
        sorted_ids = state.ids[:owned][order]
        position = np.minimum(np.searchsorted(sorted_ids, ids[missing]), owned - 1)
        found = sorted_ids[position] == ids[missing]
        index[missing[found]] = order[position[found]]
        return index

    def checkpoint_records(self, comm) -> np.ndarray:
        """Collective: the dashpot records kept since the last advance, all ranks' rows (on every rank)."""
        local = np.concatenate(self.damper_records) if self.damper_records else np.zeros((0, RECORD_COLUMNS))
        return allgather_rows(comm, local, RECORD_COLUMNS)

    def restore_records(self, rows, comm) -> None:
        """Records from a checkpoint: rank 0 keeps them all, the next advance shares them (exchange)."""
        rows = np.asarray(rows, dtype=float)
        if rows.size and (rows.ndim != 2 or rows.shape[1] != RECORD_COLUMNS):
            raise kinds.StateMismatch(f"solid '{self.name}': the checkpoint's contact records have {rows.shape[-1]} "
                                      f"columns, this version writes {RECORD_COLUMNS} (a checkpoint of an older "
                                      f"version, taken with contacts on the surface)")
        rows = rows.reshape(-1, RECORD_COLUMNS)
        self.damper_records = [rows.copy()] if len(rows) and comm.rank == 0 else []

    # ------------------------------------------------------------ checkpoints
    def _window_sums(self, comm) -> tuple:
        """Collective: the counter-forces accumulated since the last advance summed over the ranks,
        and every rank's dashpot records of the window (on every rank)."""
        total = self.accumulated_forces.copy()
        heat = self.triangle_surface.vertex_heat.copy()
        if comm.size > 1:
            comm.Allreduce(MPI.IN_PLACE, total, op=MPI.SUM)
            if self.conducting:
                comm.Allreduce(MPI.IN_PLACE, heat, op=MPI.SUM)
        return total, self.checkpoint_records(comm), heat

    def state_dict(self) -> dict:
        """Collective: the sub-cycling window so far (the surface's vertices are the wall's state: written
        as one array for all ranks, so the whole surface is brought back first)."""
        self._refresh_whole()
        total, records, heat = self._window_sums(self.solid.comm)
        state = {"accumulated_forces": kinds.global_array(total), "damper_records": kinds.global_array(records)}
        if self.triangle_surface.blended:
            local = np.concatenate(self.share_rows) if self.share_rows else np.zeros((0, SHARE_COLUMNS))
            state["share_rows"] = kinds.global_array(allgather_rows(self.solid.comm, local, SHARE_COLUMNS))
        if self.conducting:
            state["accumulated_heat"] = kinds.global_array(heat)
        if self.frame is not None:
            state["frame_work"] = kinds.scalar(float(self.frame_work()))
            state["frame_vertex_velocities"] = kinds.global_array(self._frame_vertex_velocities)
            state["relative_vertex_velocities"] = kinds.global_array(self._relative_vertex_velocities)
            state["pending_frame_displacements"] = kinds.global_array(self._pending_frame_part)
            state["pending_forces"] = kinds.global_array(self._summed_pending_forces())
        return state

    def _book_frame_work(self, mean_force) -> None:
        """The frame's work on the particles through the last advance's jump of the surface: the particles felt
        the window's mean force before it and feel `mean_force` (this window's) after it; the contacts'
        energy changed by the trapezoid of the two times the jump (second order, and booked when the
        particles' energy shows the jump: booking it at the advance would run one step ahead of them)."""
        if self._pending_forces is not None:
            self.frame_work_local -= 0.5 * float(np.sum((self._pending_forces + mean_force) * self._pending_frame_part))
        self._pending_forces = np.array(mean_force, dtype=float)

    def frame_work(self) -> float:
        """Collective: work [J] the moving frame did on the particles through this surface (all ranks), kept on
        rank 0 from here on; 0 without motion."""
        if self.frame is None:
            return 0.0
        comm = self.solid.comm
        total = comm.allreduce(self.frame_work_local, op=MPI.SUM) if comm.size > 1 else self.frame_work_local
        self.frame_work_local = total if comm.rank == 0 else 0.0
        return float(total)

    def load_state_dict(self, state: dict) -> None:
        """After the solid's state: its surface positions mirrored; the window's sums kept on rank 0
        (the rank-local partial sums of the run that wrote them are gone)."""
        comm = self.solid.comm
        stored = np.asarray(state["accumulated_forces"])
        if stored.shape != self.accumulated_forces.shape:  # a global array: every rank refuses together
            raise kinds.StateMismatch(
                f"solid '{self.name}': its contact surface has {len(stored)} nodes in the checkpoint, "
                f"{len(self.accumulated_forces)} in this scene (solids[].contact or the mesh changed): the surface's "
                f"pending loads cannot continue, so it is refused even with --force")
        self.refresh_vertices()
        self.accumulated_forces[:] = stored if comm.rank == 0 else 0.0
        self.restore_records(state["damper_records"], comm)
        # Rank 0 keeps the window's share rows too (a checkpoint without them: none were pending, or an older
        # version's, whose records carried the blended contacts' normal springs).
        shares = np.asarray(state.get("share_rows", np.zeros((0, SHARE_COLUMNS))), dtype=float).reshape(-1, SHARE_COLUMNS)
        self.share_rows = [shares.copy()] if len(shares) and comm.rank == 0 else []
        self.dissipation_correction_local = 0.0
        if (self.frame is not None) != ("frame_work" in state):
            raise kinds.StateMismatch(f"solid '{self.name}': motion: differs between this scene and the checkpoint")
        if self.frame is not None:
            self.frame_work_local = float(state["frame_work"]) if comm.rank == 0 else 0.0
            self._frame_vertex_velocities = np.array(state["frame_vertex_velocities"], dtype=float)
            self._relative_vertex_velocities = np.array(state["relative_vertex_velocities"], dtype=float)
            self._pending_frame_part = np.array(state["pending_frame_displacements"], dtype=float)
            pending = np.asarray(state["pending_forces"], dtype=float)
            self._pending_forces = None if not len(pending) else (pending if comm.rank == 0 else 0.0 * pending)
        if self.conducting:
            if "accumulated_heat" not in state:
                raise kinds.StateMismatch(f"solid '{self.name}': the checkpoint holds no surface heat (written "
                                          f"without heat)")
            self.triangle_surface.vertex_heat[:] = np.asarray(state["accumulated_heat"]) if comm.rank == 0 else 0.0
            self.refresh_temperatures()

    def _summed_pending_forces(self) -> np.ndarray:
        """Collective: the pending window force of a moving frame summed over the ranks ((0, 3): none yet)."""
        pending = (np.zeros((len(self.node_indices), 3)) if self._pending_forces is None
                   else self._pending_forces.copy())
        self.solid.comm.Allreduce(MPI.IN_PLACE, pending, op=MPI.SUM)
        if self._pending_forces is None:
            return np.zeros((0, 3))
        return pending

    def canonicalize(self) -> None:
        """Collective: the window's sums moved to rank 0, as a restart has them; the whole surface current and
        no selection (derived state: the next force evaluation selects anew, as after a restart)."""
        comm = self.solid.comm
        self._refresh_whole()
        self.selection = None
        self._seen_build = None
        self.triangle_surface.flag = 0.0
        self.triangle_surface.summed_flag = 0.0
        total, records, heat = self._window_sums(comm)
        self.accumulated_forces[:] = total if comm.rank == 0 else 0.0
        if self.frame is not None and self._pending_forces is not None:
            summed = self._summed_pending_forces()
            self._pending_forces = summed if comm.rank == 0 else 0.0 * summed
        self.restore_records(records, comm)
        if self.conducting:
            self.triangle_surface.vertex_heat[:] = heat if comm.rank == 0 else 0.0

    def remember_positions(self) -> None:
        """Keep the mirrored positions before an advance (for the mean surface velocity over it)."""
        self._positions_before = self.triangle_surface.vertices.copy()
        if self._partial:
            # The displacement before the advance, for the whole surface's chord velocities (_refresh_whole).
            if self._displacement_before is None:
                self._displacement_before = self.solid.displacement_vec.duplicate()
            self.solid.displacement_vec.copy(self._displacement_before)
        if self.frame is not None:
            self._body_before = self._body_positions.copy()
            self._time_before = self.solid.time

    def refresh_vertices(self, interval=None) -> None:
        """Collective: mirror the solid's current surface positions, and as velocities the mean over the
        last advance of length `interval` (the displacement increment / interval: the velocity at the
        particles' half step, see driver.py); interval None: the solid's own half-step velocities."""
        if self.frame is not None:
            self._refresh_moving_frame(interval)
            return
        self._last_interval = interval if self._positions_before is not None else None
        if self.selection is None or interval is None:
            self._stale = True  # gathered whole just below
            self._refresh_whole()
            return
        surface = self.triangle_surface
        if surface.summed_flag > 0.0:
            # A rank's surface nodes drifted beyond a quarter margin after an earlier advance (every rank has the
            # same summed flag): all select anew.
            self._stale = True
            self._refresh_whole()
            self._select(self._region)
            return
        # The vertices stand where remember_positions found them: their rows are the positions before the advance.
        contact = self.solid.contact_surface()
        displacements, velocities = self.selection.gather.pair_views(self.solid.displacement_vec,
                                                                     self.solid.velocity_vec)
        chosen.refresh_rows(self.selection.rows, contact.reference_positions, displacements, velocities,
                            -1.0 if self._last_interval is None else float(self._last_interval),
                            surface.vertices, surface.vertex_velocities)
        surface.mark_vertices_moved()
        self._stale = True
        drift = self.selection.drift(contact.local_values(self.solid.displacement_vec), contact.owned_local_rows)
        surface.flag = 1.0 if drift > 0.25 * self._margin else 0.0

    # ------------------------------------------------------------ partial gather
    def allow_partial_gather(self, allowed: bool = True) -> None:
        """Called by the simulation (every rank alike): whether this surface may gather only the part near each
        rank's particles (module docstring); never on one rank or for a solid with motion."""
        self._partial = (bool(allowed) and type(self).partial_gather and self.solid.comm.size > 1
                         and self.frame is None)
        self.triangle_surface.carry_flag = self._partial

    def _before_contacts(self, system) -> None:
        """Collective (every rank, before the surface's contacts of every step): after a list build, the
        selection is made anew when any rank's particle region left the one its selection covers."""
        if not self._partial:
            return
        state = system.state
        if state.positions_at_build is self._seen_build:  # no list build since the last look
            return
        self._seen_build = state.positions_at_build
        self._region = chosen.particle_region(state.positions_at_build[:state.owned_count], system.skin)
        self._margin = chosen.MARGIN_RADII * system.largest_radius
        self._reach = system.largest_radius + float(system.tables.cohesion_reach) + self._margin
        outside = self.selection is None or not chosen.region_within(self._region, self.selection.region,
                                                                        0.5 * self._margin)
        # One reduction per list build (a step that migrates particles and exchanges ghosts anyway).
        flag = np.array([1.0 if outside else 0.0])
        self.solid.comm.Allreduce(MPI.IN_PLACE, flag, op=MPI.MAX)
        if flag[0] > 0.0:
            self._refresh_whole()
            self._select(self._region)

    def _select(self, region) -> None:
        """Collective, with the whole surface current: a new selection for this rank's particle region."""
        contact = self.solid.contact_surface()
        rows = chosen.rows_near(self.triangle_surface.vertices, self.triangles, region, self._reach)
        self.selection = chosen.SurfaceSelection(contact.select(rows), region,
                                                 contact.owned_values(self.solid.displacement_vec))
        self.selections += 1
        self.triangle_surface.flag = 0.0
        self.triangle_surface.summed_flag = 0.0

    def _refresh_whole(self) -> None:
        """Collective (the same on every rank: _stale is): bring every vertex to the solid's current state as
        the last refresh computed it (positions, the chord velocities over the last advance, temperatures)."""
        if not self._stale:
            return
        contact = self.solid.contact_surface()
        positions, velocities = contact.gather(self.solid.displacement_vec, self.solid.velocity_vec)
        if self._last_interval is not None:
            # The positions before the advance as the previous refresh computed them: X + u before.
            before = (contact.reference_positions + contact.whole.vector(self._displacement_before)
                      if self._displacement_before is not None and self.selection is not None
                      else self._positions_before)
            velocities = (positions - before) / self._last_interval
        self.triangle_surface.set_vertices(positions, velocities)
        if self.conducting and self.selection is not None:
            self.triangle_surface.set_temperature(contact.gather_scalar(self.solid.temperature_vec))
        self._stale = False

    def _refresh_moving_frame(self, interval) -> None:
        """refresh_vertices of a solid with motion: world positions, the chord velocities split into the
        frame's and the elastic part, and the frame's work on the particles over the advance."""
        solid = self.solid
        body_positions, body_velocities = solid.contact_surface().gather(solid.displacement_vec, solid.velocity_vec)
        positions, velocities = solid.frame_to_world(body_positions, body_velocities)
        if interval is not None and getattr(self, "_positions_before", None) is not None:
            displacement = positions - self._positions_before
            elastic = (body_positions - self._body_before) @ self.frame.rotation(self._time_before).T
            frame_part = displacement - elastic
            velocities = displacement / interval
            self._frame_vertex_velocities = frame_part / interval
            self._relative_vertex_velocities = elastic / interval
            self._pending_frame_part = frame_part
        else:
            self._frame_vertex_velocities = self.frame.frame_velocities(positions, solid.time)
            self._relative_vertex_velocities = velocities - self._frame_vertex_velocities
        self._body_positions = body_positions
        self.triangle_surface.set_vertices(positions, velocities)


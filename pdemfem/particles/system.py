"""The particle system: state, neighbour list, walls, decomposition and the DEM step.

Parallel model: space is cut into one box per rank (RCB, weighted by cost).
A rank integrates the particles it owns (rows [0, owned_count) of the state)
and holds ghost copies of neighbours' particles within the ghost cutoff.  A
pair across a box boundary is computed on both ranks, each keeping the force
on its own particle, so no forces travel back.  At a list rebuild particles
migrate to the rank owning their position, with their contact history; between
rebuilds only ghost positions and velocities are exchanged.

Other bodies the particles touch (mesh walls, cylinders, FE surfaces) plug in
as *contributors*: objects with
  name                                   unique name (for wall_force lookups)
  move(dt)                               advance the body's own kinematics before forces
  add_forces(system, first, last)        add contact forces of owned particles [first, last) to
                                         system.state.forces/torques; return (elastic, dissipated, contacts)
  local_totals()                         this rank's totals to sum over the ranks (1-D array, when comm.size > 1)
  take_summed_totals(summed)             take them back summed (pdemfem.parallel.reductions: one SUM per step)
  step_heat                              with heat on: heat [J] the body gave this rank's particles in
                                         the last add_forces (read after it)
Their per-particle contact history lives in state.fields (ParticleState.add_field),
so it is reordered and migrated with the particles.

Particles come and go at list rebuilds: streams append new ones (add_particles), and the
particles beyond the domain box or in an outlet (pdemfem.particles.outlet) are removed.  With heat
on, the heat content they bring in and take out is booked where that happens (carried_heat).

Rigid clumps (pdemfem.clumps.bodies.ClumpBodies, `clumps`): their member spheres are rows of the
state; the clumps integrate the free spheres and the bodies (members follow their bodies) and sum
the members' loads onto the bodies after the contacts.  A clump leaving the domain box is removed whole.
A body and its members belong to the rank owning its centre of mass; whole bodies migrate at rebuilds.
"""
from __future__ import annotations

import logging
import math

import numpy as np
from mpi4py import MPI

from pdemfem.contact import layout
from pdemfem import state_dict as kinds
from pdemfem.contact import forces as generic_contact_kernels
from pdemfem.contact.specialized import contact_kernels
from pdemfem.contact.registry import history_signs
from pdemfem.kept_rows import KeptRows
from pdemfem.neighbors.cells import cell_grid, cell_indices, out_of_order_runs, sort_by_cell
from pdemfem.neighbors.verlet import VerletList
from pdemfem.parallel.decomposition import Decomposition, add_pair_costs, recursive_bisection, touching_pair_ends
from pdemfem.parallel.exchange import GhostExchange, migrate
from pdemfem.parallel.reductions import StepReductions
from pdemfem.particles.energy import NO_CLUMP_BODIES, energy_leaving, particle_energy_sums
from pdemfem.particles.heat import (NO_HEAT_FLOWS, NO_TEMPERATURES, CarriedHeat, HeatLedger, heat_content,
                                    update_temperatures)
from pdemfem.particles.integrate import kick, kick_drift, outside_domain

log = logging.getLogger("pdemfem")

# Load-balance weights (per owned particle, in units of a listed pair that is apart), estimated on the
# settle scene's packed bed: the pair kernel takes 4.2 ms for 108,708 listed pairs of which 54,979 touch
# (docs/performance.md), i.e. ~70 ns per touching pair if a distance test costs ~5 ns; a particle's own
# share of the step (integration, list build, ghost update) is ~25 ns.  On the 28k settle scene on 2 ranks
# these weights cut the faster rank's waiting from 2.0 to 0.5-0.8 s per 1500 steps (docs/parallel.md).
PARTICLE_COST = 5.0
CONTACT_COST = 12.0

# Re-sort the owned particles by cell when the cell order has more breaks than this fraction of them.
REORDER_FRACTION = 0.1


class ParticleSystem(kinds.StateComponent):
    def __init__(self, state, walls, tables, gravity, dt: float, skin: float, comm, contributors=(),
                 domain_box=None, periodic_axes=(), rebalance_threshold: float = 1.2, largest_radius: float = 0.0,
                 outlets=None, heat_capacities=None, clumps=None):
        """heat_capacities: c [J/(kg K)] per contact-table row, needed when the tables' composition has
        heat on (pdemfem.particles.heat); the state then carries temperatures.  clumps: the rigid
        clumps (pdemfem.clumps.bodies.ClumpBodies) whose members are rows of `state`, or None."""
        self.state = state
        self.clumps = clumps
        self.walls = walls
        self.tables = tables
        self.contact_kernels = contact_kernels(tables.composition)  # pair_forces, plane_wall_forces
        self._set_apart = self.contact_kernels.set_apart_buffer()  # pair_forces' first evaluations
        specialized_ranks = comm.allreduce(int(self.contact_kernels is not generic_contact_kernels))
        if 0 < specialized_ranks < comm.size:
            # Where some rank could not write the composition's module, all run the generic kernels: the ranks
            # compute the pairs they share with one code (the two agree only to round-off).
            if comm.rank == 0:
                log.warning("contact kernels: %d of %d ranks have no writable kernel folder; every rank runs the "
                            "generic pair and wall kernels (a slower pair loop, docs/contact_models.md)",
                            comm.size - specialized_ranks, comm.size)
            self.contact_kernels = generic_contact_kernels
        self.gravity = np.asarray(gravity, dtype=float)
        self.dt = float(dt)
        self.skin = float(skin)
        self.comm = comm
        self.contributors = list(contributors)
        self.heat = bool(tables.composition & layout.HEAT)
        if self.heat and (state.temperatures is None or heat_capacities is None):
            raise ValueError("heat is on in the contact tables: the particles need temperatures and the "
                             "materials heat capacities")
        self.heat_capacities = (np.ascontiguousarray(heat_capacities, dtype=float) if self.heat
                                else np.zeros(0))
        # Heat the walls and surfaces gave the particles (plane walls, then contributors).
        self.heat_ledger = HeatLedger(list(walls.names) + [body.name for body in self.contributors])
        # Heat content inserted particles brought in and removed ones took out (heat on only).
        self.carried_heat = CarriedHeat()
        self.heat_step_ratio = 0.0  # largest dt sum(H) / (m c) of an owned particle so far (this rank)
        self.largest_heat_step_ratio = 0.0  # the same over the ranks, at the last energies() call
        self.thermal_energy = 0.0  # heat content m c T of the particles [J], at the last energies() call
        self.neighbors = VerletList(history_signs(tables.composition),
                                    np.ascontiguousarray(tables.coefficients[:, :, layout.COHESION_REACH]))
        self.rebalance_threshold = float(rebalance_threshold)
        self.domain_lower = np.full(3, -np.inf)
        self.domain_upper = np.full(3, np.inf)
        self.periodic_lengths = np.zeros(3)
        if domain_box is not None:
            self.domain_lower, self.domain_upper = (np.array(corner, dtype=float) for corner in domain_box)
            for axis in periodic_axes:
                index = "xyz".index(axis)
                self.periodic_lengths[index] = self.domain_upper[index] - self.domain_lower[index]
        self.decomposition = None
        self.ghosts = None
        self.elastic_energy = 0.0
        self.dissipated_energy = 0.0
        self.contact_count = 0
        # This rank's deepest contact overlap since the run monitor last read it, as a fraction of the smaller
        # radius: [sphere-sphere, sphere-plane wall, sphere-triangle surface] (the monitor reduces and resets it at
        # its checks).
        self.deepest_overlaps = np.zeros(3)
        self.lost_particles = 0
        self.lost_energy = 0.0  # kinetic + rotational + potential energy the domain box's removals took out [J]
        self.nonfinite_particles = 0  # of lost_particles: removed because a position became inf/NaN
        self.largest_displacement = 0.0  # of an owned particle since the last list build, after the last drift
        self.fastest_speed = 0.0  # largest particle speed at the last energies() call
        self.rebalances = 0
        self._touching_pair_ends = 0  # owned ends of touching listed pairs, at the last force evaluation
        self._owned_loads_zeroed = False  # set by step() between its kick_drift and the force evaluation
        self.reductions = StepReductions()  # the step's two collectives: one MAX, one SUM
        self._migrated_records = KeptRows()  # where migrate writes the records kept and arrived
        # Leave the step's SUM in flight until the next step's MAX (finish_step_sum): set by the Simulation
        # when nothing reads the summed values within its steps; until finished, the energies, the contact
        # count, the plane walls' forces and the contributors' totals hold the step before's sums.
        self.defer_step_sum = False
        # Called with the step's sums in place (the Simulation's mean surface forces).
        self.after_step_sum = None
        # `largest_radius`: of the particles inserted later (streams), which the ghost cutoff must cover too.
        largest_radius = max(float(state.radii.max()) if state.count else 0.0, float(largest_radius))
        self.largest_radius = comm.allreduce(largest_radius, op=MPI.MAX)
        # Sinks (pdemfem.particles.outlet) that take particles at list rebuilds, as the domain box does.
        self.outlets = outlets
        # A ghost is needed when it can touch (or, cohesive, still hold on to) an owned particle before the
        # next rebuild.
        self.ghost_cutoff = 2.0 * self.largest_radius + self.skin + tables.cohesion_reach
        if clumps is not None:
            # A member is owned by its body's rank and sticks out of that rank's box by up to its offset
            # from the centre of mass; so may the partner it touches on the other side of a cut.
            clumps.comm = comm
            self.ghost_cutoff += 2.0 * clumps.protrusion(state, comm)
        self._check_periodic_lengths()
        self._rebuild(force_rebalance=True)
        self._booking_wall_work = False  # this first evaluation starts the trapezoid (_take_step_sums)
        self._compute_forces()
        # Power of the plane walls on the particles at the last force evaluation (see _take_step_sums).
        self.walls.previous_power = self._plane_power()
        self._booking_wall_work = True
        if self.heat:
            # The first step's forces come from this evaluation, its heat does not: a step moves the heat
            # of its own evaluation (step), so nothing is booked for this one.
            self.heat_ledger.pending[:] = 0.0
            for contributor in self.contributors:
                if getattr(contributor, "vertex_heat", None) is not None:
                    contributor.vertex_heat[:] = 0.0
            # Particles the first build removed (beyond the domain box) were never in the starting heat
            # content (the first history row is taken after it): they took nothing out of it.
            self.carried_heat.pending[:] = 0.0

    def _check_periodic_lengths(self):
        from pdemfem.errors import SceneError

        if self.largest_radius == 0.0:
            return  # no particle now or later (streams count): nothing can touch its own image, as check says
        for axis in range(3):
            length = self.periodic_lengths[axis]
            if 0 < length <= 2.0 * self.ghost_cutoff:
                raise SceneError(f"domain.box ({'xyz'[axis]})",
                                 f"the periodic length {length:g} m is not larger than twice the interaction cutoff "
                                 f"{self.ghost_cutoff:g} m (largest diameter + skin)",
                                 "enlarge the periodic domain or reduce the skin")

    # ---------------------------------------------------------------- the step
    def step(self) -> None:
        state, dt = self.state, self.dt
        owned = state.owned_count
        if self.clumps is not None:
            largest_displacement_squared = self.clumps.first_half(state, self.gravity, dt)
        else:
            largest_displacement_squared = kick_drift(owned, state.positions, state.velocities,
                                                      state.angular_velocities, state.forces, state.torques,
                                                      state.inverse_mass, state.inverse_inertia, self.gravity,
                                                      0.5 * dt, dt, state.positions_at_build)
        # Either zeroed the owned rows' loads; a rebuild (new rows, new order) clears this.
        self._owned_loads_zeroed = True
        if self.comm.size > 1:
            largest_displacement_squared = self.reductions.largest(self.comm, largest_displacement_squared)
            self.finish_step_sum()  # the last step's SUM, if left in flight: both waited for at one point
        # Read by the run monitor's runaway stop (same value on every rank).
        self.largest_displacement = math.sqrt(largest_displacement_squared)
        self.walls.move(dt)
        for contributor in self.contributors:
            contributor.move(dt)
        # A pair (or particle-wall pair) can only close the skin if the two moved more than skin in sum.
        largest_displacement = self.largest_displacement + self.walls.largest_displacement_since_build()
        if 2.0 * largest_displacement > self.skin:
            self._rebuild()
            self._compute_forces()
        else:
            # The ghosts' update travels while the pairs of two owned particles are computed.
            if self.ghosts is not None:
                self.ghosts.start_update(state)
            self._compute_forces(self.ghosts)
        if self.clumps is not None:
            self.clumps.second_half(state, self.gravity, dt)
        else:
            kick(state.owned_count, state.velocities, state.angular_velocities, state.forces, state.torques,
                 state.inverse_mass, state.inverse_inertia, self.gravity, 0.5 * dt)
        if self.heat:
            ratio = update_temperatures(state.owned_count, state.temperatures, state.heat_flows, state.mass,
                                        state.material_index, self.heat_capacities, dt)
            self.heat_step_ratio = max(self.heat_step_ratio, ratio)

    def _plane_power(self) -> float:
        return -float(np.sum(self.walls.forces * self.walls.velocities))

    # ---------------------------------------------------------------- rebuild
    def canonical_rebuild(self, records=None, decomposition=None) -> None:
        """A rebuild whose outcome depends only on the particles (by id), the contact records and
        the decomposition -- not on the row order or the previous list (checkpoint/restart).

        Checkpoint steps call it in the running and in the restarted simulation alike, so the
        continuation sums every force in the same order (bit-identical on the same rank count).
        The decomposition is kept (or replaced by `decomposition`); rows are put in id order
        before the cell sort; the last step's forces and torques travel with their particles
        (velocity Verlet's first half kick needs them).  `records`: contact-history rows
        (owner id, partner id, xi) to restore instead of the current list's.
        """
        state = self.state
        for name in ("forces", "torques"):
            state.add_field(f"carry:{name}", (3,), checkpoint=False)[:] = getattr(state, name)
        if decomposition is not None:
            self.decomposition = decomposition
            self._replace_ghosts(GhostExchange(self.comm, decomposition, self.ghost_cutoff, self.periodic_lengths))
        self._rebuild(records=records, canonical=True)
        # The balance check's contact count from the new list and positions, as a restarted run finds it (not the
        # last force evaluation's, which the restarted run did not make): the next rebuild decides alike.
        self._touching_pair_ends = self._count_touching_pair_ends()
        for name in ("forces", "torques"):
            setattr(state, name, state.remove_field(f"carry:{name}"))

    # ---------------------------------------------------------------- checkpoints
    def state_dict(self) -> dict:
        """Collective: the particles, their contact records, the decomposition and the running totals."""
        state = self.state
        result = {"state": state.state_dict(),
                  "contacts": self.neighbors.state_dict(state.ids, state.owned_count, self.walls.candidates)}
        if self.decomposition is not None:
            result["decomposition"] = self.decomposition.state_dict()
        if self.clumps is not None:
            result["clumps"] = self.clumps.state_dict()
        result["totals"] = {"dissipated_energy": kinds.scalar(float(self.dissipated_energy)),
                            "elastic_energy": kinds.scalar(float(self.elastic_energy)),
                            "contact_count": kinds.scalar(int(self.contact_count)),
                            "lost_particles": kinds.scalar(int(self.lost_particles)),
                            "lost_energy": kinds.scalar(float(self.lost_energy)),
                            "rebalances": kinds.scalar(int(self.rebalances))}
        if self.heat:
            result["totals"]["heat_given"] = kinds.global_array(self.heat_ledger.settle(self.comm))
            result["totals"]["heat_carried"] = kinds.global_array(self.carried_heat.settle(self.comm))
            result["totals"]["heat_step_ratio"] = kinds.scalar(float(self.comm.allreduce(self.heat_step_ratio,
                                                                                         op=MPI.MAX)))
        return result

    def load_state_dict(self, stored: dict) -> None:
        """Collective: this rank's share of the stored particles (id order) and the records of their
        contacts; the stored decomposition when it was written on as many ranks as run now (else the
        next rebuild re-partitions).  canonicalize() then rebuilds from exactly this."""
        self.state.load_state_dict(stored["state"])
        if self.clumps is not None:
            if "clumps" not in stored:
                raise kinds.StateMismatch("holds no clumps (written by a scene without clumps)")
            self.clumps.load_state_dict(stored["clumps"])
        self.neighbors = VerletList(self.neighbors.history_signs, self.neighbors.cohesion_reach)
        self.neighbors.load_state_dict(stored["contacts"], self.comm, self.state.ids)
        decomposition = stored.get("decomposition")
        if decomposition is not None and len(decomposition["boxes"]) == self.comm.size:
            self.decomposition = Decomposition.from_state_dict(decomposition)
            self._replace_ghosts(GhostExchange(self.comm, self.decomposition, self.ghost_cutoff, self.periodic_lengths))
        else:
            self.decomposition = None
            self._replace_ghosts(None)
        totals = stored["totals"]
        self.dissipated_energy = float(totals["dissipated_energy"])
        self.elastic_energy = float(totals["elastic_energy"])
        self.contact_count = int(totals["contact_count"])
        self.lost_particles = int(totals["lost_particles"])
        self.lost_energy = float(totals.get("lost_energy", 0.0))  # (checkpoints before it was booked: none)
        self.rebalances = int(totals["rebalances"])
        if self.heat:
            if "heat_given" not in totals:
                raise kinds.StateMismatch("holds no heat totals (written by a scene without heat)")
            self.heat_ledger.total[:] = np.asarray(totals["heat_given"], dtype=float)
            self.heat_ledger.pending[:] = 0.0
            self.heat_step_ratio = float(totals["heat_step_ratio"])
            self._load_carried_heat(totals)

    def _load_carried_heat(self, totals: dict) -> None:
        """The heat carried in and out so far (every heated checkpoint of this format holds them)."""
        if "heat_carried" not in totals:
            raise kinds.StateMismatch("holds no heat_in / heat_out totals")
        self.carried_heat.total[:] = np.asarray(totals["heat_carried"], dtype=float)
        self.carried_heat.pending[:] = 0.0

    def canonicalize(self) -> None:
        self.canonical_rebuild()

    def add_particles(self, new_state) -> None:
        """Collective: append `new_state`'s particles (new ids, touching nothing; this rank's share) as
        owned rows and rebuild the list.  The last step's loads (checkpointed fields that do not
        migrate: forces, torques) travel with their particles, as in canonical_rebuild: the next
        step's first half kick needs them; the new particles start with none."""
        state = self.state
        records = self._contact_records()  # while the ghost rows are there
        state.drop_ghosts()
        if self.heat:
            self.carried_heat.book_in(heat_content(new_state.count, new_state.temperatures, new_state.mass,
                                                   new_state.material_index, self.heat_capacities))
        state.append_particles(new_state)
        carried = [name for name in state.field_names("checkpoint") if not state.registry[name].migrate]
        for name in carried:
            values = state.array(name)
            state.add_field(f"carry:{name}", values.shape[1:], values.dtype, checkpoint=False)[:] = values
        self._rebuild(records=records)
        for name in carried:
            state._set(name, state.remove_field(f"carry:{name}"))

    def _rebuild(self, force_rebalance: bool = False, records=None, canonical: bool = False) -> None:
        """Migrate, (re)balance, sort, exchange ghosts and rebuild the list, keeping contact history."""
        state = self.state
        self._owned_loads_zeroed = False
        if records is None:
            records = self._contact_records()
        rebalance, before = False, None
        if ((self.comm.size > 1 or self.decomposition is None or np.any(self.periodic_lengths > 0))
                and (not canonical or self.decomposition is None)):
            if force_rebalance or self.decomposition is None:
                rebalance = True
            else:
                # The ranks' cost totals from counts (a pass over every listed pair for the per-particle costs
                # took 0.4-0.5 ms of a 2-rank rebuild of the settle bed, and a rebalance is rare).
                before = self._imbalance(np.array([self._cost_total()]))
                rebalance = before > self.rebalance_threshold
        # Per-particle costs only matter for balancing several ranks (taken before the ghosts are dropped).
        costs = None
        if rebalance:
            costs = self._particle_costs() if self.comm.size > 1 else np.ones(state.owned_count)
        state.drop_ghosts()
        self._wrap_periodic()
        kept = self._remove_lost()
        if not np.all(kept) and len(records):
            # Removed particles' records have no owner left (migrate looks owners up by id).
            records = records[np.isin(records[:, 0].astype(np.int64), state.ids[:state.owned_count])]
        if self.comm.size > 1 or self.decomposition is None or np.any(self.periodic_lengths > 0):
            if rebalance:
                costs = costs[kept]
                if before is None:
                    before = self._imbalance(costs)
                self.decomposition = recursive_bisection(self.comm, state.positions, costs[:state.owned_count],
                                                         self.domain_lower, self.domain_upper, self.ghost_cutoff)
                self._replace_ghosts(GhostExchange(self.comm, self.decomposition, self.ghost_cutoff,
                                                   self.periodic_lengths))
                self.rebalances += 1
                self._pending_rebalance_log = before
            if self.comm.size > 1:
                destinations = self.decomposition.owners(state.positions)
                if self.clumps is not None:  # members go with their bodies, whole bodies move
                    destinations = self.clumps.member_destinations(state, destinations, self.decomposition)
                records = migrate(self.comm, state, destinations, records, self._migrated_records,
                                  self.neighbors.record_buffer)
                if self.clumps is not None:
                    self.clumps.migrate_bodies(self.comm, self.decomposition)
        if canonical and state.owned_count:
            state.reorder(np.argsort(state.ids, kind="stable"))  # the cell sort is stable: ties by id
        ghost_selection = self._sort_owned()
        if self.ghosts is not None:
            self.ghosts.plan_and_send(state, ghost_selection)
        self.neighbors.build(state, self.skin, records, self.ghosts.late_rows(state) if self.ghosts else None)
        self.walls.build_candidates(state.positions[:state.owned_count], state.radii[:state.owned_count],
                                    self.skin + self.tables.cohesion_reach, len(self.neighbors.history_signs))
        self.walls.restore_history(state.ids, state.owned_count, records)
        state.record_build_positions()
        if self.clumps is not None:
            self.clumps.refresh_rows(state)
        if getattr(self, "_pending_rebalance_log", None) is not None and self.comm.size > 1:
            after = self._imbalance(np.ones(state.owned_count) + self._rows_per_particle())
            if self.comm.rank == 0:
                log.info("rebalance %d: imbalance %.3f -> %.3f", self.rebalances, self._pending_rebalance_log, after)
            self.last_imbalance = (self._pending_rebalance_log, after)
        self._pending_rebalance_log = None

    def _contact_records(self) -> np.ndarray:
        """The contact records of the particle pairs and of the plane walls (pdemfem.neighbors.history): one per
        pair where no particle migrates or has a periodic image (each pair's two particles stay owned here)."""
        one_per_pair = self.comm.size == 1 and not np.any(self.periodic_lengths > 0)
        return self.neighbors.contact_records(self.state.ids, self.state.owned_count, self.walls.candidates,
                                              one_per_pair)

    def _particle_costs(self) -> np.ndarray:
        """Cost per owned particle, in units of a listed pair that is apart (a distance test, ~5 ns):
        PARTICLE_COST for its own step (integration, list build, ghosts), 1 per listed pair, and
        CONTACT_COST more per touching pair (the contact law).  Without the contacts' weight a settling
        bed cut horizontally looked balanced (listed pairs 1.07) while its lower rank held 5x the
        contacts and did most of the work."""
        state = self.state
        costs = np.full(state.count, PARTICLE_COST)
        neighbors = self.neighbors
        if self._list_is_current():
            add_pair_costs(neighbors.row_particles, neighbors.offsets, neighbors.partners, state.positions,
                           state.radii, CONTACT_COST, costs)
        return costs[:state.owned_count]

    def _cost_total(self) -> float:
        """This rank's total of _particle_costs without the pass over the pairs: PARTICLE_COST per owned particle,
        1 per listed pair end on an owned particle (two for a pair of owned particles, one for a pair with a ghost)
        and CONTACT_COST more per touching one, counted as the last force evaluation's contacts (or, after a
        canonical rebuild, the list's: _touching_pair_ends)."""
        neighbors = self.neighbors
        total = PARTICLE_COST * self.state.owned_count
        if self._list_is_current():
            interior = neighbors.interior_pair_count
            total += 2 * interior + (neighbors.pair_count - interior) + CONTACT_COST * self._touching_pair_ends
        return float(total)

    def _list_is_current(self) -> bool:
        """Whether the list has pairs and one row per row of the state (rows appended or removed since its build
        leave it stale until the next one)."""
        return bool(self.neighbors.pair_count) and len(self.neighbors.row_particles) == self.state.count

    def _count_touching_pair_ends(self) -> int:
        state, neighbors = self.state, self.neighbors
        if not self._list_is_current():
            return 0
        return int(touching_pair_ends(neighbors.row_particles, neighbors.offsets, neighbors.partners, state.positions,
                                      state.radii, state.owned_count))

    def _rows_per_particle(self) -> np.ndarray:
        state = self.state
        counts = np.zeros(state.count)
        if self._list_is_current():
            first, second = self.neighbors.pair_rows()
            counts += np.bincount(first, minlength=state.count)
            counts += np.bincount(second, minlength=state.count)
        return counts[:state.owned_count]

    def _imbalance(self, costs: np.ndarray) -> float:
        local = np.array([np.sum(costs[:self.state.owned_count])], dtype=float)
        totals = np.empty(self.comm.size)
        self.comm.Allgather(local, totals)
        mean = float(totals.mean())
        return float(totals.max()) / mean if mean > 0 else 1.0

    def _wrap_periodic(self) -> None:
        positions = self.state.positions
        for axis in np.flatnonzero(self.periodic_lengths > 0):
            lower, length = self.domain_lower[axis], self.periodic_lengths[axis]
            positions[:, axis] = lower + np.mod(positions[:, axis] - lower, length)

    def _remove_lost(self) -> np.ndarray:
        """Remove particles outside the domain along non-periodic axes (counted, never kept at NaN).

        Returns the mask of the owned particles that stayed."""
        state = self.state
        bounded = np.isfinite(self.domain_lower) & (self.periodic_lengths == 0)
        outside, nonfinite = outside_domain(state.owned_count, state.positions, self.domain_lower,
                                            self.domain_upper, bounded)
        carried = self._energy_carried_out(outside)
        if self.clumps is not None:  # a clump goes whole (counted as its member spheres)
            outside, bodies, energies = self.clumps.remove_leaving(state, outside, self.gravity, 0.5 * self.dt)
            carried += self._book_leaving_bodies(bodies, energies)
        totals = np.array([np.count_nonzero(outside), nonfinite, carried], dtype=float)
        if self.comm.size > 1:
            self.comm.Allreduce(MPI.IN_PLACE, totals, op=MPI.SUM)
        lost, nonfinite = int(round(totals[0])), int(round(totals[1]))
        if lost:
            self.lost_particles += lost
            self.nonfinite_particles += nonfinite
            self.lost_energy += float(totals[2])
        if self.outlets is not None:  # particles an outlet takes are counted there (collective)
            outside |= self.outlets.take(state, ~outside, self.gravity, self.comm, 0.5 * self.dt)
        if np.any(outside):
            if self.heat:
                self.carried_heat.book_out(self._heat_content_of(np.flatnonzero(outside)))
            state.keep(np.flatnonzero(~outside))
        return ~outside

    @property
    def removes_leaving(self) -> bool:
        """Whether the domain box bounds an axis that is not periodic (particles beyond it are removed)."""
        return bool(np.any(np.isfinite(self.domain_lower) & (self.periodic_lengths == 0)))

    def _book_leaving_bodies(self, bodies: np.ndarray, energies: np.ndarray) -> float:
        """Collective while the clumps are replicated: count the bodies that left (ClumpBodies.lost) and return
        this rank's share of their energy for the sum over the ranks.  Right after a checkpoint was read every
        rank holds every body and one body's members may sit on two ranks until they migrate, so each of those
        ranks reports the body: it is counted and booked once, on rank 0 (it was booked twice on 2 ranks)."""
        clumps, comm = self.clumps, self.comm
        if clumps.replicated and comm.size > 1:
            reports = comm.allgather((bodies, energies))
            every_id = np.concatenate([ids for ids, _ in reports])
            every_energy = np.concatenate([values for _, values in reports])
            _, first = np.unique(every_id, return_index=True)
            if comm.rank != 0:
                return 0.0
            bodies, energies = every_id[first], every_energy[first]
        clumps.lost += len(bodies)
        return float(np.sum(energies[np.isfinite(energies)]))

    def _energy_carried_out(self, outside: np.ndarray) -> float:
        """The energy the free spheres among the owned rows `outside` carry out (energy_leaving; a clump's is its
        body's: Clumps.remove_leaving)."""
        leaving = outside
        if self.clumps is not None:
            from pdemfem.clumps.bodies import BODY_FIELD

            leaving = outside & (self.state.fields[BODY_FIELD][:self.state.owned_count] < 0)
        return energy_leaving(self.state, np.flatnonzero(leaving), self.gravity, 0.5 * self.dt)

    def _heat_content_of(self, rows: np.ndarray) -> float:
        """m c T [J] of the given rows, each particle's term as heat_content (thermal_energy) takes it."""
        state = self.state
        return heat_content(len(rows), state.temperatures[rows], state.mass[rows], state.material_index[rows],
                            self.heat_capacities)

    def _sort_owned(self):
        """Order owned particles by cell so that neighbours are close in memory.  Returns the ghost selection
        (GhostExchange.select) for the rows as they are after it, or None without ghosts to send."""
        state = self.state
        selection = None
        if self.ghosts is not None and self.ghosts.targets:
            selection = self.ghosts.select(state.positions[:state.owned_count])
        if state.owned_count < 2:
            return selection
        lower, size, dimensions = cell_grid(state.positions, 2.0 * self.largest_radius + self.skin)
        cells = cell_indices(state.positions, lower, size, dimensions)
        cell_count = int(np.prod(dimensions))
        misplaced_sent = sent_count = 0
        if selection is not None:
            # The particles sent as ghosts go last, in cell order among themselves: the pass over the pairs
            # with a ghost (after the ghosts' update arrived) and the update's packing then read one compact
            # block, where after the interior pass they were spread over every row of cells of an upright
            # cut and missed the caches.
            sent = self.ghosts.sent_rows_mask(selection, state.owned_count)
            sent_count = int(np.count_nonzero(sent))
            misplaced_sent = sent_count - int(np.count_nonzero(sent[state.owned_count - sent_count:]))
            cells += cell_count * sent
            cell_count *= 2
        permutation, _ = sort_by_cell(cells, cell_count)
        # The sort only buys memory locality (the list build bins by cell itself): skip the copy of
        # every per-particle array while few rows break the cell order and few sent ones are out of their block.
        if (out_of_order_runs(permutation) > REORDER_FRACTION * state.owned_count
                or misplaced_sent > REORDER_FRACTION * sent_count):
            state.reorder(permutation)
            if selection is not None:
                # Renumbered, not selected again: the same rows (0.06-0.13 ms a 2-rank rebuild of the 28k bed).
                selection = self.ghosts.renumber(selection, permutation)
        return selection

    # ---------------------------------------------------------------- forces
    def _replace_ghosts(self, ghosts) -> None:
        if self.ghosts is not None:
            self.ghosts.close()  # its send buffers and requests go with it
        self.ghosts = ghosts

    def _compute_forces(self, ghosts_in_flight=None) -> None:
        """The loads of this step.  `ghosts_in_flight`: the GhostExchange whose start_update was called; the
        pairs with a ghost wait for its finish_update, the pairs of two owned particles and the walls do not."""
        state, tables, walls, neighbors = self.state, self.tables, self.walls, self.neighbors
        # Since the step's kick_drift only the ghost rows' loads are left to zero (one pass fewer over memory).
        first = state.owned_count if self._owned_loads_zeroed else 0
        self._owned_loads_zeroed = False
        if first < state.count:  # (on one rank there are no ghosts: no slices to make)
            state.forces[first:] = 0.0
            state.torques[first:] = 0.0
        walls.forces.fill(0.0)
        owned = state.owned_count
        if self.heat:
            temperatures, heat_flows = state.temperatures, state.heat_flows
            heat_flows[:] = 0.0
        else:
            temperatures, heat_flows = NO_TEMPERATURES, NO_HEAT_FLOWS
        pair_arguments = (neighbors.partners, neighbors.history, state.ids, owned, state.positions, state.velocities,
                          state.angular_velocities, state.radii, state.mass, state.inverse_inertia,
                          state.material_index, tables.coefficients, tables.composition, self.dt, state.forces,
                          state.torques, temperatures, heat_flows, self._set_apart)
        elastic, dissipated, contacts, deepest_pair = self.contact_kernels.pair_forces(*neighbors.interior,
                                                                                       *pair_arguments)
        pair_contacts = contacts
        if walls.count:
            wall_elastic, wall_dissipated, wall_contacts, deepest_wall = self.contact_kernels.plane_wall_forces(
                walls.candidate_particles, walls.candidate_walls, walls.points, walls.normals, walls.velocities,
                walls.material_index, walls.candidate_history, state.positions, state.velocities,
                state.angular_velocities, state.radii, state.mass, state.inverse_inertia, state.material_index,
                tables.coefficients, tables.composition, self.dt, state.forces, state.torques, walls.forces,
                temperatures, heat_flows, walls.temperatures, self.heat_ledger.pending)
            elastic += wall_elastic
            dissipated += wall_dissipated
            contacts += wall_contacts
            if deepest_wall > self.deepest_overlaps[1]:
                self.deepest_overlaps[1] = deepest_wall
        if ghosts_in_flight is not None:
            ghosts_in_flight.finish_update(state)
        if len(neighbors.boundary[0]):
            boundary_elastic, boundary_dissipated, boundary_contacts, deepest_boundary = \
                self.contact_kernels.pair_forces(*neighbors.boundary, *pair_arguments)
            elastic += boundary_elastic
            dissipated += boundary_dissipated
            contacts += boundary_contacts
            deepest_pair = max(deepest_pair, deepest_boundary)
            pair_contacts += boundary_contacts
        # Two owned ends per contact of two owned particles; a contact with a ghost has one here and is booked on
        # one of its two ranks (about half of them on each): the balance check's estimate (_cost_total).
        self._touching_pair_ends = 2 * pair_contacts
        if deepest_pair > self.deepest_overlaps[0]:
            self.deepest_overlaps[0] = deepest_pair
        for index, contributor in enumerate(self.contributors, start=walls.count):
            extra_elastic, extra_dissipated, extra_contacts = contributor.add_forces(self, 0, owned)
            if self.heat:
                self.heat_ledger.pending[index] += contributor.step_heat
            elastic += extra_elastic
            dissipated += extra_dissipated
            contacts += extra_contacts
        if self.clumps is not None:
            self.clumps.sum_loads(state)
        if self.comm.size > 1:
            self.reductions.start_sum(self.comm, (elastic, dissipated, contacts), walls.forces, self.contributors)
            if not self.defer_step_sum:
                self.finish_step_sum()
        else:
            self._take_step_sums(elastic, dissipated, contacts)

    def finish_step_sum(self) -> None:
        """Collective: finish the step's SUM over the ranks if it is in flight (defer_step_sum)."""
        if self.reductions.pending:
            scalars = self.reductions.finish_sum()
            self._take_step_sums(scalars[0], scalars[1], int(round(scalars[2])))

    def finish_clump_step(self) -> None:
        """The clump bodies' load sum and second half, if left pending for the next step (ClumpBodies.
        defer_second_half): their loads, kick, omega and members' velocities and spins, for whoever reads the
        state between steps."""
        if self.clumps is not None:
            self.clumps.finish_second_half(self.state)

    def _take_step_sums(self, elastic, dissipated, contacts) -> None:
        """Book the step's totals over the ranks (the plane walls' forces and the contributors' totals are
        already summed in place)."""
        self.elastic_energy = float(elastic)
        self.dissipated_energy += float(dissipated)
        self.contact_count = int(contacts)
        # Work done on the particles by moving walls, -F_wall . v_wall: the trapezoid of the powers at the
        # force evaluations before and after the walls' move (velocity Verlet's kinetic energy takes the two
        # forces' mean; one force booked the step's work a step early: a first-order error wherever a wall's
        # force jumps, e.g. a grain on a conveyor turning from slipping to rolling).  Walls at rest: nothing.
        walls = self.walls
        # count_nonzero: numpy's any() on a 5 x 3 array costs 1.8 us, a tenth of the fixed cost of a step.
        if self._booking_wall_work and np.count_nonzero(walls.velocities):
            power = self._plane_power()
            walls.work += 0.5 * (walls.previous_power + power) * self.dt
            walls.previous_power = power
        if self.after_step_sum is not None:
            self.after_step_sum()

    # ---------------------------------------------------------------- queries
    def owned_range(self) -> tuple:
        return 0, self.state.owned_count

    def global_count(self) -> int:
        return self.comm.allreduce(self.state.owned_count) if self.comm.size > 1 else self.state.owned_count

    def energies(self) -> dict:
        """Energies summed over the ranks.  The same pass leaves the largest particle speed over the
        ranks in `fastest_speed` (inf when a velocity is not finite), for the run monitor."""
        state = self.state
        if self.clumps is not None:  # members count with their bodies (translation and rotation)
            kinetic, rotational, potential, fastest_squared = self.clumps.energy_sums(state, self.gravity)
        else:
            kinetic, rotational, potential, fastest_squared = particle_energy_sums(
                state.owned_count, state.mass, state.velocities, state.angular_velocities, state.inverse_inertia,
                state.positions, self.gravity, NO_CLUMP_BODIES)
        thermal = (heat_content(state.owned_count, state.temperatures, state.mass, state.material_index,
                                self.heat_capacities) if self.heat else 0.0)
        local = np.array([kinetic, rotational, potential, thermal])
        largest = np.array([fastest_squared, self.heat_step_ratio])
        if self.comm.size > 1:
            self.comm.Allreduce(MPI.IN_PLACE, local, op=MPI.SUM)
            self.comm.Allreduce(MPI.IN_PLACE, largest, op=MPI.MAX)
        self.fastest_speed = float(np.sqrt(largest[0]))
        self.largest_heat_step_ratio = float(largest[1])
        self.thermal_energy = float(local[3])
        return {
            "kinetic_energy": float(local[0]),
            "rotational_energy": float(local[1]),
            "potential_energy": float(local[2]),
            "elastic_energy": self.elastic_energy,
            "dissipated_energy": self.dissipated_energy,
            "wall_work": self.walls.work,
        }

"""The coupled step: DEM step, counter-forces to the FE nodes, FE advance, surface update.

Order per DEM step: the particle system integrates the particles
and computes every contact, including those with the mirrored FE surfaces at
their current positions; the counter-forces are spread onto FE nodes; the solid
advances; the mirrored vertices move to the new nodal positions.

Time levels (fem_every = 1).  The particle step n -> n+1 drifts the particles to
x^{n+1} and evaluates the contact force F^{n+1} with the particle velocity
v^{n+1/2} (after the first half kick).  For particles and solid to form one
central-difference (velocity Verlet) system, the surface must be at u^{n+1} and
move with v^{n+1/2} at that moment, and the solid must then take its step
t^{n+1} -> t^{n+2} with F^{n+1} as the load at t^{n+1}.  The solid therefore
runs one step *ahead* of the particles between coupling calls: at construction
(after the initial contact evaluation F^0) the driver primes it with the step
t^0 -> t^1 under F^0.  Without the prime the surface is one step stale (the
force F^{n+1} loads the solid's step t^n -> t^{n+1}), a first-order error in the
exchanged energy (measured: the energy error of an elastic impact halves with dt
instead of quartering; tests/test_coupling_momentum.py).

The surface velocity handed to the contacts is the mean velocity over the last
advance, (u^{T} - u^{T-h}) / h (h = the advance interval), i.e. exactly the
displacement increment the particles see divided by their step: for fem_every = 1
that is v^{n+1/2}, the particle's own time level, also when the solid sub-steps.

Momentum.  The particles receive F^{n+1} dt (two half kicks around t^{n+1}); the
solid receives the same impulse through its step.  With the particles' momentum
measured at the half level, m v^{n+1} + dt/2 F^{n+1} (the velocity after the next
first half kick), particles + solid conserve linear momentum to round-off; the
barycentric spreading conserves force and moment exactly.

Contact dashpots.  The damping part of each contact force is not held over the interval:
the solid applies it to the surface nodes implicitly at every FE sub-step and the particles
receive the balancing impulse after the advance (coupling/dampers.py: a dashpot held
constant over the sub-steps, with the surface velocity of the previous interval, pumps
energy into the solid's high modes; this keeps momentum exact and the exchange dissipative).

Sub-cycling knobs:
- fem_every = k: the solid advances every k DEM steps over k dt with the mean
  (impulse-preserving) load of those steps.  The prime then covers (k+1)/2 dt,
  so the surface the particles see during a window of k steps sits at the mean
  time of the window, and the window's mean force loads the solid at that time
  (second-order centring; the surface itself is frozen over k steps, the first-
  order part of the sub-cycling error, measured in tests/test_coupling_ball.py).
- when the FE critical step is below the interval, Solid.advance covers each
  interval with the fewest equal stable sub-steps (fem_substeps[name]).
"""
from __future__ import annotations

import numpy as np
from mpi4py import MPI

from pdemfem import state_dict as kinds


class CouplingDriver(kinds.StateComponent):
    def __init__(self, solids: dict, surfaces: list, dt: float, fem_every: int = 1, prime: bool = True,
                 comm=None, window_springs: bool = False):
        """Collective.  Call after the particle system has evaluated its initial contacts (F^0).
        comm: the simulation's communicator (default: the solids').  window_springs: the contact springs over
        the FE sub-steps (coupling/dampers.py) also act on advances of several DEM steps (fem_every > 1)."""
        self.window_springs = bool(window_springs)
        self.comm = comm if comm is not None else next((solid.comm for solid in solids.values()), MPI.COMM_SELF)
        self.solids = solids
        self.surfaces = surfaces
        self.dt = float(dt)
        self.fem_every = int(fem_every)
        self.steps_since_advance = 0
        self.fem_substeps = {name: 1 for name in solids}
        self.advances = 0
        # How far (s) the solid runs ahead of the particles right after an advance.
        self.lead = 0.5 * (self.fem_every + 1) * self.dt
        if prime and solids:
            self.prime()

    def prime(self) -> None:
        """Collective: advance the solids over the lead (k+1)/2 dt with the initial contacts' forces F^0.

        The load is scaled so that the solid receives F^0 dt, the impulse the particles get from F^0."""
        for surface in self.surfaces:
            surface.collect_contact_forces(keep_dampers=False)
        self._kick_free_axes(self.dt / self.lead, self.lead)
        for surface in self.surfaces:
            surface.send_forces_to_solid(self.dt / self.lead, dampers=False, interval=self.lead, steps=1)
        self._advance_solids(self.lead)

    def _advance_solids(self, interval: float) -> None:
        for surface in self.surfaces:
            surface.remember_positions()
            surface.send_heat_to_solid(interval)
        for name, solid in self.solids.items():
            self.fem_substeps[name] = solid.advance(interval)
        for solid in self._free_axes():
            if solid.frame.moving(solid.time - interval):
                solid.frame.drift(interval)
        for surface in self.surfaces:
            surface.refresh_vertices(interval)
            if surface.conducting:
                surface.refresh_temperatures()
            # The records move between ranks only when particles can have moved since they were taken.
            surface.balance_dampers(self.dt, exchange=self.fem_every > 1)
        self.advances += 1

    def _free_axes(self) -> list:
        return [solid for solid in self.solids.values()
                if getattr(solid, "frame", None) is not None and solid.frame.carried_mass is not None]

    def _kick_free_axes(self, scale: float, interval: float) -> None:
        """Collective, before the forces are sent: each free axis (fem/frame.py, free sinkage) takes the vertical
        force the particles put on its solid over the window (scale x the accumulated forces, the mean the solid
        receives; summed over the ranks: one reduction per advance, only in scenes with a free axis)."""
        free = self._free_axes()
        if not free:
            return
        forces = np.zeros(len(free))
        for index, solid in enumerate(free):
            for surface in self.surfaces:
                if surface.solid is solid:
                    forces[index] += scale * surface.accumulated_forces[:, 2].sum()
        if self.comm.size > 1:
            self.comm.Allreduce(MPI.IN_PLACE, forces, op=MPI.SUM)
        for force, solid in zip(forces, free):
            if solid.frame.moving(solid.time):  # held before motion.start
                solid.frame.kick(float(force), float(solid.gravity[2]), interval)

    def after_particle_step(self) -> None:
        """Collective: collect counter-forces, and every fem_every steps advance the solids."""
        for surface in self.surfaces:
            surface.collect_contact_forces()
        self.steps_since_advance += 1
        if self.steps_since_advance < self.fem_every:
            return
        interval = self.steps_since_advance * self.dt
        # Mean load over the interval: the same impulse as the per-step loads.
        self._kick_free_axes(1.0 / self.steps_since_advance, interval)
        for surface in self.surfaces:
            surface.send_forces_to_solid(1.0 / self.steps_since_advance, interval=interval,
                                         steps=self.steps_since_advance, springs=self.window_springs)
        self._advance_solids(interval)
        self.steps_since_advance = 0

    def pending_impulse(self) -> dict:
        """Per surface, the impulse [N s] collected since the last advance but not yet given to the solid
        (force sums x dt, this rank's contacts): what the solid still owes the particles within a window."""
        return {surface.name: surface.accumulated_forces.sum(axis=0) * self.dt for surface in self.surfaces}

    def dashpot_dissipation(self) -> float:
        """Collective: energy [J] the contact dashpots on solid surfaces dissipated beyond what the contact
        kernels booked (coupling/dampers.py): the particle-side correction minus the dashpots' work on
        the solids' nodes."""
        local = np.array([sum(surface.dissipation_correction_local for surface in self.surfaces)
                          - sum(solid.damper_work_local for solid in self.solids.values())])
        self.comm.Allreduce(MPI.IN_PLACE, local, op=MPI.SUM)
        return float(local[0])

    # ------------------------------------------------------------ checkpoints
    def state_dict(self) -> dict:
        """Collective: where the sub-cycling window stands and the dashpot dissipation so far."""
        state = {"steps_since_advance": kinds.scalar(int(self.steps_since_advance)),
                 "advances": kinds.scalar(int(self.advances)),
                 "fem_substeps": kinds.scalar({name: int(count) for name, count in self.fem_substeps.items()})}
        if self.solids:
            state["dashpot_dissipation"] = kinds.scalar(self.dashpot_dissipation())
            # Each rank's running sums as they stand, so that a restart on as many ranks goes on adding to the same
            # numbers (collapsed into the total above, the books drifted from the uninterrupted run's by round-off).
            local = np.array(self._dashpot_sums(), dtype=float)
            by_rank = np.empty((self.comm.size, local.size))
            self.comm.Allgather(local, by_rank)
            state["dashpot_sums_by_rank"] = kinds.global_array(by_rank)
        return state

    def _dashpot_sums(self) -> list:
        """This rank's running sums: each surface's particle-side correction, then each solid's damper work."""
        return ([surface.dissipation_correction_local for surface in self.surfaces]
                + [solid.damper_work_local for solid in self.solids.values()])

    def load_state_dict(self, state: dict) -> None:
        """After the solids and surfaces (which restart their rank-local dashpot sums at zero): on as many ranks
        as the checkpoint's, each rank takes up its own running sums; on another rank count rank 0 takes their
        sums over the checkpoint's ranks (each sum keeps its size: the dissipation is their difference, which
        cancels most of their digits); from a checkpoint without them, the dissipation up to the checkpoint is
        booked once, on rank 0's first surface."""
        self.steps_since_advance = int(state["steps_since_advance"])
        self.advances = int(state["advances"])
        self.fem_substeps.update({name: int(count) for name, count in state["fem_substeps"].items()})
        by_rank = np.asarray(state.get("dashpot_sums_by_rank", np.zeros((0, 0))), dtype=float)
        if by_rank.ndim == 2 and by_rank.shape[1:] == (len(self._dashpot_sums()),):
            if by_rank.shape[0] == self.comm.size:
                sums = by_rank[self.comm.rank]
            else:
                sums = by_rank.sum(axis=0) if self.comm.rank == 0 else np.zeros(by_rank.shape[1])
            for surface, value in zip(self.surfaces, sums):
                surface.dissipation_correction_local = float(value)
            for solid, value in zip(self.solids.values(), sums[len(self.surfaces):]):
                solid.damper_work_local = float(value)
        elif self.surfaces and self.comm.rank == 0:
            self.surfaces[0].dissipation_correction_local = float(state.get("dashpot_dissipation", 0.0))

    def refresh_surfaces(self) -> None:
        """Collective: re-mirror the solids' state (e.g. after a restart set the solid state directly)."""
        for surface in self.surfaces:
            surface.refresh_vertices(None)

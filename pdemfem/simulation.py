"""Simulation: builds everything from a scene and runs the step loop.

Data flows one way: scene -> built state (arrays, PETSc objects) -> step loop
-> writers.  Nothing is written to disk before the whole scene has been built
and validated, so a bad scene leaves no output directory behind.
"""
from __future__ import annotations

import logging
import math
import numbers
from functools import partial
from pathlib import Path
from types import SimpleNamespace

import numpy as np
from mpi4py import MPI

from pdemfem.clumps.bodies import ClumpBodies
from pdemfem.contact.tables import build_contact_tables
from pdemfem.coupling.check import HELD_FORCE_MARGIN, WINDOW_SPRING_SHARE, blended_transfer, coupling_assessment
from pdemfem.coupling.driver import CouplingDriver
from pdemfem.coupling.surface import CoupledSurface
from pdemfem.errors import SceneError, SolverError
from pdemfem.io.history import IntervalMean
from pdemfem.io.simulation_io import SimulationIO
from pdemfem.monitor import DivergenceMonitor
from pdemfem.parallel.api_safety import abort_on_uncaught_exceptions, collective_errors, private_communicators
from pdemfem.particles.heat import material_heat_capacities
from pdemfem.particles.insert import insert_particles
from pdemfem.particles.outlet import Outlets
from pdemfem.particles.stream import ParticleStreams, stream_radius_range
from pdemfem.particles.state import ParticleState
from pdemfem.particles.system import ParticleSystem
from pdemfem.schedule import Schedule
from pdemfem.scene import derived
from pdemfem.scene.inputs import (solid_errors_named, start_solids, start_surfaces, validate_geometry,
                                   validate_scene_coordinates)
from pdemfem.scene.loader import input_file_digests, load_scene, output_directory, resolve_path
from pdemfem.walls.factory import build_contributor_walls
from pdemfem.walls.plane import PlaneWalls

# The skin a scene gets when it names none, as a fraction of the smallest radius:
# larger skins rebuild the list less often but carry more non-touching pairs.
DEFAULT_SKIN_FRACTION = 0.3

log = logging.getLogger("pdemfem")


class Simulation:
    """A coupled DEM(-FEM) simulation built from a validated scene."""

    @collective_errors
    def __init__(self, scene, base_dir: Path, comm=None, output_dir=None, restart=None, force: bool = False):
        # Private duplicates of the user's communicator (pdemfem.parallel.api_safety).
        self.comm, self.error_comm = private_communicators(comm if comm is not None else MPI.COMM_WORLD)
        abort_on_uncaught_exceptions(self.comm)
        self.scene = scene
        self.base_dir = Path(base_dir)
        self.output_dir = output_directory(scene, self.base_dir, output_dir)
        # What the files the scene names held when the run read them (checkpoints keep it: a restart from an
        # edited mesh is refused).  Read on one rank: every rank then agrees on the refusal.
        self.input_digests = self.comm.bcast(input_file_digests(scene, self.base_dir) if self.comm.rank == 0 else None)
        self.solids = self._build_solids()
        # dt "auto" without particles takes the solids' FE critical step (collective).
        solid_step = (min(solid.critical_time_step() for solid in self.solids.values())
                      if self.solids and not scene.particles else None)
        self.dt = float(derived.time_step(scene, solid_critical_step=solid_step))
        self.time = 0.0
        self.step_count = 0
        # The coupled-stability warnings of `pdemfem check` (collective): run prints them, the monitor names them;
        # with coupling.transfer auto the solids a point load dimples get the blended gap.
        self.coupling_warnings, interval_limit, self.point_loaded_solids = (
            coupling_assessment(scene, self.solids, self.dt) if self.solids else ([], math.inf, set()))
        if scene.time.dt == "auto" and self.dt > HELD_FORCE_MARGIN * interval_limit:
            # dt auto keeps its promise on yielding solid surfaces too: within the step a held contact force
            # allows their lightest node (an explicit time.dt above that is refused, below).
            self.dt = HELD_FORCE_MARGIN * interval_limit
            self.coupling_warnings, interval_limit, self.point_loaded_solids = coupling_assessment(
                scene, self.solids, self.dt)
        self.particle_system = self._build_particles()
        for surface in self.coupled_surfaces:
            surface.particle_system = self.particle_system
            # A stream's insertion tests every triangle on every rank: those scenes keep the whole gather.
            surface.allow_partial_gather(self.streams is None)
        self.fem_every = self._allowed_fem_every(interval_limit)
        # Contact springs over a window of DEM steps (coupling/dampers.py) while the window is within half the held
        # force's interval limit: an impact on a sub-stepped plate at fem_every 2 then lost 8.4e-3 of its energy
        # instead of gaining 2.0e-2 (second order in dt instead of first), while a resting sphere at the limit (57
        # steps) gained 0.74 J of 2182 J with them and nothing without.
        self.coupling = CouplingDriver(self.solids, self.coupled_surfaces, self.dt, fem_every=self.fem_every,
                                       comm=self.comm,
                                       window_springs=self.fem_every * self.dt <= WINDOW_SPRING_SHARE * interval_limit)
        self.io = SimulationIO(self, force=force)
        self.stopped_by = None  # the signal's name when a run stopped early (SIGTERM/SIGUSR1)
        # Contact forces on walls and solids summed over the steps since the last history row: the
        # rows report their mean over the output interval (an instantaneous sample of a granular
        # contact force is mostly the noise of single impacts).
        self.surface_force_means = IntervalMean()
        self.particle_system.after_step_sum = self._add_surface_forces
        # Within a call of step() only the coupling (the FE advance, its surfaces' reselection flag) reads the
        # sums over the ranks of a step: without solids each step's SUM is finished at the next step's MAX.
        self.particle_system.defer_step_sum = not self.solids
        if self.particle_system.clumps is not None:
            # Likewise the clump bodies' load sum and second half kick (and their members' velocities) wait for
            # the next step's first half, unless the coupling reads (and its dashpot balance writes) the
            # particles' velocities between steps.
            self.particle_system.clumps.defer_second_half = not self.solids
        self.runaway_displacement = math.inf  # set by the run monitor (pdemfem.monitor) during run
        if restart is not None:
            self.io.restore(restart, force=force)

    # ------------------------------------------------------------ construction
    def _allowed_fem_every(self, interval_limit: float) -> int:
        """coupling.fem_every, lowered where the held contact force would overshoot a yielding surface's
        lightest node over the interval (docs/stability.md); a DEM step above that limit is refused."""
        requested = self.scene.coupling.fem_every
        if requested * self.dt <= interval_limit:
            return requested
        if self.dt > interval_limit:
            raise SceneError(
                "time.dt",
                f"dt = {self.dt:.4g} s holds a contact force on a yielding solid surface longer than its lightest "
                f"node allows ({interval_limit:.4g} s: S_n dt^2 / (4 m) > 1, see `pdemfem check`)",
                f"give time.dt <= {interval_limit:.4g} s, or coarsen the solid's contact surface")
        allowed = max(1, int(math.floor(interval_limit / self.dt)))
        if self.comm.rank == 0:
            log.warning("coupling.fem_every lowered from %d to %d: a longer interval than %.4g s lets the held "
                        "contact force overshoot a yielding surface node (docs/stability.md)",
                        requested, allowed, interval_limit)
        return allowed

    @classmethod
    def from_file(cls, path, comm=None, output_dir=None, restart=None, force: bool = False):
        """Build from a scene file; `restart`: a checkpoint (or its directory) to continue from,
        `force`: accept a checkpoint of a scene whose physics changed (scene hash mismatch)."""
        scene, base_dir = load_scene(path)
        return cls(scene, base_dir, comm=comm, output_dir=output_dir, restart=restart, force=force)

    @classmethod
    def from_dict(cls, data: dict, comm=None, base_dir=None, output_dir=None, restart=None, force: bool = False):
        scene, base_dir = load_scene(data, base_dir=base_dir)
        return cls(scene, base_dir, comm=comm, output_dir=output_dir, restart=restart, force=force)

    def _build_particles(self) -> ParticleSystem:
        scene = self.scene
        validate_scene_coordinates(scene)  # before the insertion bins them (as `pdemfem check`)
        inserted = insert_particles(scene)
        # Streams insert particles later (pdemfem.particles.stream): their radii count for the skin and cutoffs.
        streamed = stream_radius_range(scene)
        radius_bounds = ([float(inserted.radii.min()), float(inserted.radii.max())] if len(inserted.radii) else []) \
            + (list(streamed) if streamed else [])
        tables = build_contact_tables(scene, characteristic_speed=derived.expected_impact_speed(scene),
                                      largest_radius=max(radius_bounds, default=0.0))
        group_material = np.array([tables.material_names.index(group.material) for group in scene.particles],
                                  dtype=np.int32)
        group_density = np.array([scene.materials[group.material].density for group in scene.particles])
        heat = scene.heat_enabled
        group_temperature = np.array([scene.heat.default_temperature if group.initial_temperature is None
                                      else group.initial_temperature for group in scene.particles])
        total = len(inserted.radii)
        self.inserted_count = total
        # Every rank places all particles identically (ids = insertion order) and keeps an
        # even slice; the first list build then moves each particle to the rank owning its box.
        mine = slice(total * self.comm.rank // self.comm.size, total * (self.comm.rank + 1) // self.comm.size)
        groups = inserted.group_index[mine]
        plane_walls = [wall for wall in scene.walls if wall.kind == "plane"]
        state = ParticleState(
            ids=np.arange(total, dtype=np.int64)[mine],
            material_index=group_material[groups] if total else np.zeros(0, np.int32),
            radii=inserted.radii[mine],
            densities=group_density[groups] if total else np.zeros(0),
            positions=inserted.positions[mine],
            velocities=inserted.velocities[mine],
            angular_velocities=inserted.angular_velocities[mine],
            # Heat off: no temperature is allocated, moved, checkpointed or written.
            temperatures=(group_temperature[groups] if total else np.zeros(0)) if heat else None,
        )
        clumps = None
        if inserted.clumps is not None:
            member_mass = np.zeros(total)
            for index, template in inserted.clumps.templates.items():
                rows = np.flatnonzero((inserted.group_index == index))
                member_mass[rows] = np.tile(template.member_mass, len(rows) // len(template.member_mass))
            ClumpBodies.attach(state, inserted.member_body[mine], inserted.member_offsets[mine], member_mass[mine])
            clumps = ClumpBodies.from_insertion(inserted.clumps)
        count = total
        walls = PlaneWalls(plane_walls, tables.material_names)
        # Mesh and cylinder walls, and the solids' contact surfaces, plug into the particle system as contributors.
        self.contributor_walls = build_contributor_walls(scene.walls, tables.material_names,
                                                         partial(resolve_path, self.base_dir))
        self.coupled_surfaces = [
            CoupledSurface(self.solids[config.name], tables.surface_row(config.name, config.material),
                           blended=blended_transfer(scene, config.name, self.point_loaded_solids))
            for config in scene.solids if config.contact
        ]
        self.contributor_walls += [surface.triangle_surface for surface in self.coupled_surfaces]
        # The checks `pdemfem check` makes, before anything is written: coordinates, domain.box, periodic
        # lengths, particles starting behind or deep in a wall or a solid's surface, or inside a solid.
        validate_geometry(
            scene, inserted, [(wall.name, wall.vertices) for wall in self.contributor_walls if hasattr(wall, "vertices")],
            surfaces=start_surfaces(scene, self.contributor_walls,
                                    [(surface.name, surface.triangle_surface.vertices, surface.triangle_surface.triangles)
                                     for surface in self.coupled_surfaces]),
            solids=start_solids(scene, self.solids), comm=self.comm)
        smallest_radius = min(radius_bounds, default=1.0)
        skin = scene.neighbors.skin or DEFAULT_SKIN_FRACTION * smallest_radius
        self.streams = ParticleStreams.from_scene(scene, tables.material_names, next_id=total, dt=self.dt)
        self.outlets = Outlets.from_scene(scene)
        return ParticleSystem(state, walls, tables, scene.gravity, self.dt, skin, self.comm,
                              contributors=self.contributor_walls,
                              domain_box=scene.domain.box, periodic_axes=scene.domain.periodic,
                              rebalance_threshold=scene.parallel.rebalance_threshold,
                              largest_radius=max(radius_bounds, default=0.0), outlets=self.outlets,
                              heat_capacities=material_heat_capacities(scene, tables.material_names) if heat else None,
                              clumps=clumps)

    def _build_solids(self) -> dict:
        """Deformable solids, each starting in static equilibrium under its constant loads."""
        if not self.scene.solids:
            return {}
        from pdemfem.fem.solid import Solid

        solids = {}
        for config in self.scene.solids:
            material = self.scene.materials[config.material]
            # With heat on, a solid whose material gives both thermal keys conducts (a `thermal:` block makes
            # it conduct and requires them); otherwise it is adiabatic and nothing thermal is allocated.
            conducts = (self.scene.heat_enabled and material.conductivity is not None
                        and material.heat_capacity is not None)
            with solid_errors_named(self.scene):  # a misnamed group: its scene key, with a "did you mean"
                solid = Solid(config, material, gravity=self.scene.gravity, comm=self.comm, base_dir=self.base_dir,
                              heat=conducts)
            held = self.comm.allreduce(int(solid.constrained_dofs.sum()))
            if held:
                solid.static_solve()
            # else: a free body cannot be solved statically; it starts undeformed and at rest.
            solids[config.name] = solid
        return solids

    # ------------------------------------------------------------ stepping
    @collective_errors
    def step(self, count: int = 1) -> None:
        """Advance `count` steps; during `run`, stop early when a particle runs away (moves further
        than the monitor's limit since the list build; the check that follows stops the run)."""
        if isinstance(count, bool) or not isinstance(count, numbers.Integral) or count < 0:
            # (int(2.5) ran 2 steps, range(-5) none, without a word)
            raise ValueError(f"Simulation.step(count): count is a whole number of steps >= 0, got {count!r}")
        system = self.particle_system
        for _ in range(int(count)):
            if self.streams is not None:
                self.streams.insert_due(self)  # the insertion events due at this step's start
            system.step()
            if self.solids:
                self.coupling.after_particle_step()
            self.step_count += 1
            self.time = self.step_count * self.dt
            if system.largest_displacement > self.runaway_displacement:
                break
        # The last step's sums over the ranks, if still in flight, and the clumps' second half, if pending:
        # everything read between calls has them.
        system.finish_step_sum()
        system.finish_clump_step()

    def _add_surface_forces(self) -> None:
        """The step's surface forces into their interval mean (called with the step's sums in place)."""
        if not self.contributor_walls:  # plane walls alone: their force rows, in the scene's order
            self.surface_force_means.add(self.particle_system.walls.forces)
        else:
            self.surface_force_means.add([self.wall_force(name) for name in self._surface_names()])

    @property
    def output_interval(self) -> float:
        return self.scene.output.every or self.scene.time.end / 100.0

    def output_schedule(self) -> Schedule:
        """The steps of the history rows and field outputs (every output.every)."""
        return Schedule(self.output_interval, self.dt)

    @collective_errors
    def run(self, progress: bool = True) -> None:
        """Advance to time.end, writing history rows and field series every output interval and
        checkpoints every checkpoint interval and at the end (without checkpoint.every only when stopped by a
        signal: a run that asked for no checkpoints leaves none in its directory).  SIGTERM/SIGUSR1 stop the run at the next stop
        check (every STOP_CHECK_EVERY steps, all ranks at the same step) with one final
        output step and checkpoint; `stopped_by` then names the signal.  A divergence found by
        the run monitor (pdemfem.monitor, checked at the same points) writes the output step, a
        checkpoint when checkpoint.every is set, and raises SolverError (exit 3) naming the likely
        cause; `stopped_by` is then "divergence"."""
        from pdemfem.io.signals import STOP_CHECK_EVERY, StopRequest

        end = self.scene.time.end
        total_steps = derived.steps_to_end(end, self.dt)
        outputs = self.output_schedule()
        every = self.scene.checkpoint.every
        checkpoints = Schedule(every, self.dt) if every else None
        self.io.open()
        if self.step_count == 0 or self.step_count != self.io.resume_step:  # (resume_step: None without a restart)
            # The state the run starts from (after steps taken through the API too: the series began at the first
            # scheduled row after them); a restart's is the checkpoint's row, already in the history.
            self.io.write_output()
        bar = _progress_bar(total_steps, self.step_count, progress and self.comm.rank == 0)
        stop = StopRequest()
        monitor = DivergenceMonitor(self)
        try:
            self._guarded(monitor.start)
            while self.step_count < total_steps:
                step = self.step_count
                targets = [total_steps, outputs.next_after(step), (step // STOP_CHECK_EVERY + 1) * STOP_CHECK_EVERY]
                if checkpoints:
                    targets.append(checkpoints.next_after(step))
                self.step(min(targets) - step)
                self._guarded(monitor.check)
                step = self.step_count
                at_end = step == total_steps
                if at_end or outputs.due_before_end(step, end):
                    self.io.write_output()
                elif outputs.is_due(step):
                    # The interval of the end's time ends here, a step before the end, whose row stands for it: the
                    # end's step counts for the next interval, as in a run that goes on past the end.
                    self.surface_force_means.close()
                if checkpoints and (at_end or checkpoints.due_before_end(step, end)):
                    self.io.write_checkpoint()
                if bar is not None:
                    bar.update(step - bar.n)
                    bar.set_postfix_str(f"t = {self.time:.4g} / {end:.4g} s", refresh=False)
                if not at_end and step % STOP_CHECK_EVERY == 0 and stop.should_stop(self.comm):
                    self.stopped_by = stop.signal_name or "signal"
                    self.io.write_output()
                    path = self.io.write_checkpoint()
                    if self.comm.rank == 0:
                        log.warning("%s: stopped at step %d (t = %.6g s); continue with --restart %s",
                                    self.stopped_by, step, self.time, path)
                    break
        finally:
            self.runaway_displacement = math.inf
            stop.restore()
            if bar is not None:
                bar.close()
            self.io.close()

    def _guarded(self, check) -> None:
        """Run a monitor check (collective); on divergence write the output step, and a checkpoint when
        checkpoints are on, then re-raise the SolverError (exit 3) on every rank."""
        try:
            check()
        except SolverError as error:
            self.stopped_by = "divergence"
            self.io.write_output()
            if not self.scene.checkpoint.every:
                raise
            path = self.io.write_checkpoint(diverged=True)
            earlier = self.io.last_checkpoint
            restart = (f"the last checkpoint before it is {earlier[1]} (step {earlier[0]}; latest.h5 is not moved "
                       f"to the stopped state): continue from it with --restart once fixed (with --force for a "
                       f"physics change; a fix that changes the step needs a fresh run with --force, since dt is "
                       f"stored state)" if earlier is not None else
                       "there is no checkpoint before it: run again with --force once fixed (it starts afresh, "
                       "replacing this run's outputs and the stopped state)")
            raise SolverError(error.where, f"{error.problem}\n  the state at the stop is kept for inspection in "
                                           f"{path}; {restart}", error.fix) from None

    @collective_errors
    def write_checkpoint(self):
        """Collective: write a checkpoint now (checkpoint.dir); returns its path."""
        return self.io.write_checkpoint()

    # ------------------------------------------------------------ output
    def history_columns(self) -> list:
        columns = ["time", "step", "particles", "kinetic_energy", "rotational_energy", "potential_energy",
                   "elastic_energy", "dissipated_energy", "wall_work", "contacts", "lost_particles"]
        if self.solids:
            columns += ["solid_kinetic_energy", "solid_strain_energy", "solid_load_potential"]
        if self._conducting_solids():
            columns += ["thermoelastic_work"]
        if self._prescribed_solids():
            columns += ["support_work"]
        if self._damped_solids():
            columns += ["damping_dissipated"]
        if self._moving_solids():
            columns += ["frame_work"]
        if self._free_axle_solids():
            columns += ["axle_energy"]
        if self.particle_system.removes_leaving:
            columns += ["lost_energy"]
        if self.particle_system.heat:
            columns += ["thermal_energy", "particle_thermal_energy"]
            columns += [f"heat_{name}" for name in self.particle_system.heat_ledger.names]
            columns += ["heat_in", "heat_out"]
            columns += [f"temperature_{body}_{statistic}" for body in ["particles", *self._conducting_solids()]
                        for statistic in ("min", "mean", "max")]
            columns += [f"boundary_heat_{name}_{book}" for name in self._conducting_solids()
                        for book in self.solids[name].heat.book_names]
        for name in self._surface_names():
            columns += [f"force_{name}_x", f"force_{name}_y", f"force_{name}_z"]
        for name in self._surface_names():
            columns += [f"mean_force_{name}_x", f"mean_force_{name}_y", f"mean_force_{name}_z"]
        for solid, group in self._support_groups():
            columns += [f"reaction_{solid}_{group}_x", f"reaction_{solid}_{group}_y", f"reaction_{solid}_{group}_z"]
        columns += [f"max_displacement_{name}" for name in self.solids]
        columns += [f"axle_height_{name}" for name in self._free_axle_solids()]
        if self.streams is not None or self.outlets is not None:
            columns += ["particles_in", "mass_in", "particles_out", "mass_out", "stream_energy"]
            columns += [f"mass_out_{name}" for name in (self.outlets.names if self.outlets is not None else [])]
        return columns

    def history_row(self) -> dict:
        system = self.particle_system
        row = {"time": self.time, "step": self.step_count, "particles": self.particle_count(),
               "lost_particles": system.lost_particles,
               "contacts": system.contact_count}
        row.update(self.energies())
        if system.heat:
            row.update(self.heat_given())
            row.update(self.heat_carried())
            row.update(self.temperature_statistics())
            for name in self._conducting_solids():
                for book, value in self.solids[name].boundary_heat().items():
                    row[f"boundary_heat_{name}_{book}"] = value
        names = self._surface_names()
        instantaneous = [self.wall_force(name) for name in names]
        # Before the first step of a run (or of a restart) no step has been averaged: the forces now.  A row off
        # the output schedule (the end, a stop) leaves the interval running for the next scheduled row; when the
        # end falls a step after the step of its own time's interval (time.end a multiple of output.every), that
        # interval was closed there (run) and the end's row shows its mean.  So a run extended past its end has
        # the rows of one that went on (a gate's load read +26 % and -18 % when the end's row was decided on the
        # times alone).
        on_schedule = self.output_schedule().is_due(self.step_count)
        means = self.surface_force_means.take(fallback=instantaneous, restart=on_schedule)
        for name, force, mean in zip(names, instantaneous, means):
            for axis, label in enumerate("xyz"):
                row[f"force_{name}_{label}"] = force[axis]
                row[f"mean_force_{name}_{label}"] = mean[axis]
        for solid, group in self._support_groups():
            reaction = self.solid_reaction(solid, group)
            for axis, label in enumerate("xyz"):
                row[f"reaction_{solid}_{group}_{label}"] = reaction[axis]
        for name, solid in self.solids.items():
            displacements = solid.displacements
            local = float(np.sqrt((displacements ** 2).sum(axis=1)).max()) if len(displacements) else 0.0
            row[f"max_displacement_{name}"] = self.comm.allreduce(local, op=MPI.MAX)
        for name in self._free_axle_solids():
            solid = self.solids[name]
            row[f"axle_height_{name}"] = float(solid.frame.centre(solid.time)[2])
        if self.streams is not None or self.outlets is not None:
            row.update(self.stream_totals())
        return row

    def stream_totals(self) -> dict:
        """Particles and mass [kg] the streams inserted and the outlets removed so far (every rank)."""
        totals = {"particles_in": 0, "mass_in": 0.0, "particles_out": 0, "mass_out": 0.0}
        if self.streams is not None:
            totals.update(particles_in=self.streams.inserted, mass_in=self.streams.mass_in)
        if self.outlets is not None:
            totals.update(particles_out=self.outlets.count_out, mass_out=self.outlets.mass_out)
            totals.update({f"mass_out_{name}": float(mass) for name, mass in zip(self.outlets.names,
                                                                                self.outlets.masses)})
        return totals

    def _support_groups(self) -> list:
        """(solid, group) of every fixed or prescribed group: each gets reaction_<solid>_<group>_x/y/z columns."""
        return [(config.name, group) for config in self.scene.solids
                for group in [*config.fixed, *(entry.group for entry in config.prescribed)]]

    def _surface_names(self) -> list:
        """Walls, then the solids the particles can touch: each gets force_<name>_x/y/z columns."""
        return [wall.name for wall in self.scene.walls] + [surface.name for surface in self.coupled_surfaces]

    # ------------------------------------------------------------ queries
    @property
    def particles(self):
        """The particles this rank owns, as numpy arrays (copies)."""
        state = self.particle_system.state
        first, last = self.particle_system.owned_range()
        return SimpleNamespace(
            ids=state.ids[first:last].copy(),
            radii=state.radii[first:last].copy(),
            positions=state.positions[first:last].copy(),
            velocities=state.velocities[first:last].copy(),
            angular_velocities=state.angular_velocities[first:last].copy(),
            forces=state.forces[first:last].copy(),
            temperatures=None if state.temperatures is None else state.temperatures[first:last].copy(),
        )

    @property
    def clumps(self):
        """The rigid clumps this rank owns (copies): ids, positions (centres of mass), orientations (unit quaternions
        w, x, y, z turning the clump frame of the scene's spheres into the world), velocities,
        angular_velocities (world frame), masses and principal_inertia (principal moments, ascending).
        Empty arrays without clumps.  `particles` holds their member spheres."""
        bodies = self.particle_system.clumps
        if bodies is None:
            return SimpleNamespace(ids=np.zeros(0, np.int64), positions=np.zeros((0, 3)), orientations=np.zeros((0, 4)),
                                   velocities=np.zeros((0, 3)), angular_velocities=np.zeros((0, 3)),
                                   masses=np.zeros(0), principal_inertia=np.zeros((0, 3)))
        return SimpleNamespace(ids=bodies.ids.copy(), positions=bodies.positions.copy(),
                               orientations=bodies.clump_frame_orientations(), velocities=bodies.velocities.copy(),
                               angular_velocities=bodies.angular_velocities.copy(), masses=bodies.masses.copy(),
                               principal_inertia=bodies.principal_moments.copy())

    def particle_count(self) -> int:
        """Total number of particles over all ranks."""
        return self.particle_system.global_count()

    def wall_force(self, name: str) -> np.ndarray:
        """Total contact force the particles exert on a wall or a solid's contact surface (summed over ranks)."""
        for wall in self.contributor_walls:
            if wall.name == name:
                return wall.force
        walls = self.particle_system.walls
        if name not in walls.names:
            raise KeyError(_unknown_name(name, "wall or contact solid", self._surface_names()))
        return walls.forces[walls.index(name)].copy()

    def wall_torque(self, name: str, about=(0.0, 0.0, 0.0)) -> np.ndarray:
        """Moment about the point `about` of the particles' contact forces on a mesh or cylinder wall
        (summed over ranks)."""
        for wall in self.contributor_walls:
            if wall.name == name:
                return wall.torque(about)
        if name not in self.particle_system.walls.names:
            raise KeyError(_unknown_name(name, "wall or contact solid", self._surface_names()))
        raise ValueError(f"wall_torque: wall '{name}' is a plane; torques are reported for mesh and cylinder walls")

    def contact_count(self) -> int:
        return self.particle_system.contact_count

    def energies(self) -> dict:
        energies = self.particle_system.energies()
        # Work done on the particles by moving mesh and cylinder walls; a solid's surface books only its
        # transport velocity's work (its own motion exchanges work inside the system).
        energies["wall_work"] += sum(wall.work for wall in self.contributor_walls)
        if self.solids:
            energies["dissipated_energy"] += self.dashpot_dissipation()
        if self._damped_solids():
            # What the solids' Rayleigh damping took from their elastic motion: dissipated, as the contacts' is.
            energies["damping_dissipated"] = sum(self.solids[name].damping_work for name in self._damped_solids())
            energies["dissipated_energy"] += energies["damping_dissipated"]
        energies["solid_kinetic_energy"] = sum(solid.kinetic_energy() for solid in self.solids.values())
        energies["solid_strain_energy"] = sum(solid.strain_energy() for solid in self.solids.values())
        # Potential of the solids' constant loads (gravity, tractions, point forces): -b . u.
        energies["solid_load_potential"] = -sum(solid.constant_load_vec.dot(solid.displacement_vec)
                                                for solid in self.solids.values())
        if self._prescribed_solids():
            # Work the prescribed groups' reactions fed in (zero where they hold their nodes still).
            energies["support_work"] = sum(self.solids[name].support_work for name in self._prescribed_solids())
        if self._moving_solids():
            # Work the solids' prescribed rigid motions fed in (fem/frame.py): through their frames' loads on the
            # elastic motion, and through their surfaces on the particles.
            energies["frame_work"] = (sum(solid.frame_work for solid in self.solids.values())
                                      + sum(surface.frame_work() for surface in self.coupled_surfaces))
        if self.particle_system.removes_leaving:
            # Energy the particles the domain box removed carried out (as an outlet's, in stream_energy).
            energies["lost_energy"] = self.particle_system.lost_energy
        if self._free_axle_solids():
            # A free axis's own kinetic and potential energy (the particles' work on it is in frame_work).
            energies["axle_energy"] = sum(self.solids[name].frame.axle_energy(self.solids[name].gravity[2])
                                          for name in self._free_axle_solids())
        conducting = [self.solids[name] for name in self._conducting_solids()]
        if conducting:
            # Strain energy the thermal load's refreshes put in (work fed in, like a moving wall's).
            energies["thermoelastic_work"] = sum(solid.thermoelastic_work for solid in conducting)
        if self.particle_system.heat:
            # Heat content m c T [J] (relative to 0 K) of the particles, and of the solids that conduct.
            particle_heat = self.particle_system.thermal_energy
            energies["particle_thermal_energy"] = particle_heat
            energies["thermal_energy"] = particle_heat + sum(solid.thermal_energy() for solid in conducting)
        if self.streams is not None or self.outlets is not None:
            # Energy the inserted particles brought in minus what the outlets took out (docs/streams.md).
            energies["stream_energy"] = ((self.streams.energy_in if self.streams is not None else 0.0)
                                         - (self.outlets.energy_out if self.outlets is not None else 0.0))
        return energies

    def heat_given(self) -> dict:
        """Collective: heat_<name> [J], the heat each wall or solid surface has given the particles since the
        start (negative: the particles heated it)."""
        ledger = self.particle_system.heat_ledger
        return {f"heat_{name}": float(value) for name, value in zip(ledger.names, ledger.settle(self.comm))}

    def heat_carried(self) -> dict:
        """Collective: heat_in and heat_out [J], the heat content m c T of the particles inserted (streams) and of
        those removed (outlets, the domain box) since the start; with heat_given they close the particles' heat
        balance: particle_thermal_energy(t) - particle_thermal_energy(0) = sum heat_<name> + heat_in - heat_out."""
        heat_in, heat_out = self.particle_system.carried_heat.settle(self.comm)
        return {"heat_in": float(heat_in), "heat_out": float(heat_out)}

    def _prescribed_solids(self) -> list:
        return [config.name for config in self.scene.solids if config.prescribed]

    def _damped_solids(self) -> list:
        return [name for name, solid in self.solids.items() if solid.damping_alpha != 0.0 or solid.damping_beta != 0.0]

    def _moving_solids(self) -> list:
        return [name for name, solid in self.solids.items() if solid.frame is not None]

    def _free_axle_solids(self) -> list:
        return [name for name in self._moving_solids() if self.solids[name].frame.carried_mass is not None]

    def _conducting_solids(self) -> list:
        return [name for name, solid in self.solids.items() if solid.heat is not None]

    def temperature_statistics(self) -> dict:
        """Collective: temperature_<body>_min/_mean/_max [K] of the particles (mean weighted by m c, so it is
        the temperature their heat content would have if spread evenly) and of each conducting solid's
        nodes (plain nodal mean); nan while there is no particle."""
        from mpi4py import MPI

        system = self.particle_system
        state = system.state
        owned = state.owned_count
        temperatures = state.temperatures[:owned]
        capacities = state.mass[:owned] * system.heat_capacities[state.material_index[:owned]]
        sums = np.array([float(np.dot(capacities, temperatures)), float(capacities.sum())])
        extremes = np.array([-temperatures.min() if owned else -np.inf, temperatures.max() if owned else -np.inf])
        bodies = {"particles": (sums, extremes)}
        for name in self._conducting_solids():
            nodal = self.solids[name].temperatures
            bodies[name] = (np.array([float(nodal.sum()), float(len(nodal))]),
                            np.array([-nodal.min() if len(nodal) else -np.inf, nodal.max() if len(nodal) else -np.inf]))
        row = {}
        for body, (sums, extremes) in bodies.items():
            self.comm.Allreduce(MPI.IN_PLACE, sums, op=MPI.SUM)
            self.comm.Allreduce(MPI.IN_PLACE, extremes, op=MPI.MAX)
            # No particle yet (a stream's first rows): no temperature, nan in all three (not +-inf).
            empty = not np.isfinite(extremes[1])
            row[f"temperature_{body}_min"] = float("nan") if empty else -float(extremes[0])
            row[f"temperature_{body}_mean"] = float(sums[0] / sums[1]) if sums[1] > 0 else float("nan")
            row[f"temperature_{body}_max"] = float("nan") if empty else float(extremes[1])
        return row

    def dashpot_dissipation(self) -> float:
        """Collective: energy [J] the contact dashpots on solid surfaces dissipated beyond what the contact
        kernels booked (CouplingDriver.dashpot_dissipation); part of dissipated_energy."""
        return self.coupling.dashpot_dissipation()

    def total_energy(self) -> float:
        """Everything the bookkeeping tracks; constant up to integration error when no work is
        fed in other than by moving walls (subtracted)."""
        from pdemfem.monitor import total_energy

        return total_energy(self.energies())

    def solid_reaction(self, solid: str, group: str) -> np.ndarray:
        """Total reaction force of a solid's support group (summed over ranks)."""
        if solid not in self.solids:
            raise KeyError(_unknown_name(solid, "solid", list(self.solids)))
        return self.solids[solid].reaction(group)


def _unknown_name(name: str, kind: str, known: list) -> str:
    """The message of a KeyError for a name the scene does not have: the known names, and the closest one."""
    import difflib

    close = difflib.get_close_matches(name, known, n=1, cutoff=0.6)
    return (f"no {kind} named '{name}'" + (f"; did you mean '{close[0]}'?" if close else "")
            + f" (this scene's: {', '.join(known) if known else 'none'})")


def _progress_bar(total_steps: int, done_steps: int, enabled: bool):
    if not enabled:
        return None
    from tqdm import tqdm

    return tqdm(total=total_steps, initial=done_steps, unit="step", unit_scale=True, desc="pdemfem",
                mininterval=1.0)

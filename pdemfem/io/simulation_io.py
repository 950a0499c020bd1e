"""The Simulation's output, checkpoint and restart glue (keeps simulation.py thin).

    io = SimulationIO(simulation)                   # after the Simulation is built
    io.restore(path, force)                         # restart: load a checkpoint into it
    io.open()                                       # history.csv, particles.h5/.xdmf, <solid>.h5/.xdmf
    io.write_output()                               # every output interval (collective)
    io.write_checkpoint()                           # every checkpoint interval, at a stop, at the end
    io.close()

State.  Every component of the simulation (solids, coupled surfaces, coupling, walls,
particles: `components()`) owns its state: a checkpoint is the components' `state_dict()`s
written by io/checkpoint.py (`write_state`), a restart hands each component its part back
(`load_state_dict`).  This module knows no component's fields (docs/architecture_state.md).

Exact continuation.  A checkpoint is taken at the end of a step; right after writing it
the running simulation puts itself into the *canonical* state a restart rebuilds from the
file: every component's `canonicalize()`, which for

- the particle system migrates, re-sorts (cell, then id) and rebuilds its lists with
  the decomposition kept (ParticleSystem.canonical_rebuild), carrying the last step's
  forces and torques (velocity Verlet's first half kick of the next step needs them;
  recomputing them would update the tangential springs and the dissipation twice, and
  the half-step velocities they were computed with are not stored);
- a triangle surface rebuilds its BVH from the current vertices and drops its
  candidate lists;
- a coupled surface moves the counter-forces accumulated since the last FE advance
  (sub-cycling, rank-local partial sums; written summed over the ranks) onto rank 0.

A restart builds the scene as usual, then overwrites every piece of state with the
file's and calls the same `canonicalize`, so on the same rank count (decomposition
restored from the file) the two runs sum every force in the same order: bit-identical.
On another rank count the particles are re-partitioned (RCB) and the FE vectors,
stored in the input mesh's node numbering, are read back by original node id; the
continuation then agrees to round-off.
"""
from __future__ import annotations

import csv
import logging
from pathlib import Path

import numpy as np

from pdemfem.errors import CheckpointError, OutputError
from pdemfem.io import checkpoint as ckpt
from pdemfem.io.history import HistoryWriter
from pdemfem.io.output_guard import agree_on_error, prepare_output, write_error_text
from pdemfem.scene.derived import steps_to_end
from pdemfem.scene.loader import input_files, resolve_path, scene_hash, scene_physics
from pdemfem.state_dict import StateMismatch

log = logging.getLogger("pdemfem")

# Particle output field -> ParticleState attribute.
PARTICLE_SOURCES = {"positions": "positions", "velocities": "velocities", "radii": "radii", "ids": "ids",
                    "forces": "forces", "temperature": "temperatures", "angular_velocities": "angular_velocities",
                    "torques": "torques", "materials": "material_index"}


# The clumps' series (clumps.h5/.xdmf), written with the particles' when the scene has clumps.
CLUMP_FIELDS = ("positions", "orientations", "velocities", "angular_velocities", "ids")


def checkpoint_directory(simulation) -> Path:
    return checkpoint_directory_of(simulation.scene, simulation.base_dir, simulation.output_dir)


def checkpoint_directory_of(scene, base_dir, output_dir) -> Path:
    """checkpoint.dir (relative to the scene file), default <output dir>/checkpoints."""
    configured = scene.checkpoint.dir
    if configured is None:
        return Path(output_dir) / "checkpoints"
    return resolve_path(base_dir, configured).resolve()


class SimulationIO:
    def __init__(self, simulation, force: bool = False):
        self.sim = simulation
        self.comm = simulation.comm
        self.force = force               # start afresh over an earlier run's results (output_guard)
        self._output_prepared = False
        self.written_checkpoints = []    # this run's checkpoints: the only ones pruning may delete
        self.restarted_from = None       # Checkpoint path when restored
        self.resume_step = None
        self.last_checkpoint = None      # (step, path) of the newest checkpoint written by this run
        self._history = None
        self._particles_out = None
        self._clumps_out = None
        self._solid_outputs = {}
        self._solid_layouts = {}
        self._last_output_step = None

    # ================================================================== outputs
    def open(self) -> None:
        """Collective: open history.csv and the XDMF/HDF5 series (continued after a restart)."""
        from pdemfem.io import xdmf
        from pdemfem.io.particle_output import ParticleOutput
        from pdemfem.io.solid_output import SolidOutput

        sim, comm = self.sim, self.comm
        self._prepare_output()
        xdmf.prepare_directory(sim.output_dir, comm)
        columns = sim.history_columns()
        history_path = sim.output_dir / "history.csv"
        append = sim.step_count > 0
        has_resume_row = False
        if comm.rank == 0 and append and self.resume_step is not None:
            has_resume_row, columns = _truncate_history(history_path, self.resume_step, columns)
        has_resume_row, columns = comm.bcast((has_resume_row, columns), root=0)
        if has_resume_row:
            # The checkpoint's step has its row and field step already: a run stopped there at once (diverged
            # again, or by a signal) must not write them twice.
            self._last_output_step = self.resume_step
        self._history = HistoryWriter(history_path, columns, comm.rank == 0, append=append)
        output = sim.scene.output
        if self.particle_fields():
            self._particles_out = ParticleOutput(sim.output_dir, comm, self.particle_fields(),
                                                 resume_step=self.resume_step)
            if sim.particle_system.clumps is not None:  # the bodies, beside their member spheres
                self._clumps_out = ParticleOutput(sim.output_dir, comm, CLUMP_FIELDS, name="clumps",
                                                  resume_step=self.resume_step)
        if output.solids:
            for name, solid in sim.solids.items():
                layout = self._solid_layouts[name] = _SolidOutputLayout(solid, comm)
                self._solid_outputs[name] = SolidOutput(sim.output_dir, name, comm, layout.points, layout.cells,
                                                        layout.node_offset, resume_step=self.resume_step)

    def particle_fields(self) -> list:
        """output.particles, without temperature when heat is off (the default list names it; a scene that
        asks for it explicitly without heat is refused at validation), with positions whenever any field is
        written."""
        heat = self.sim.particle_system.heat
        fields = [name for name in self.sim.scene.output.particles if heat or name != "temperature"]
        if fields and "positions" not in fields:  # the geometry: ParticleOutput writes it with any other field
            fields.insert(0, "positions")
        return fields

    def _prepare_output(self) -> None:
        """Collective, before the first write: refuse to overwrite or mix an earlier run's files
        unless this run continues it (restart) or starts afresh (force); see io/output_guard.py."""
        if self._output_prepared:
            return
        prepare_output(self.sim.output_dir, checkpoint_directory(self.sim), self.comm,
                       restart=self.restarted_from is not None, force=self.force, clear=True)
        self._output_prepared = True

    def close(self) -> None:
        if self._history is not None:
            self._history.close()
            self._history = None
        writers = [self._particles_out, self._clumps_out, *self._solid_outputs.values()]
        self._particles_out = None
        self._clumps_out = None
        self._solid_outputs = {}
        for writer in writers:
            if writer is None:
                continue
            try:
                writer.close()  # the series' index, up to its last step
            except OSError as error:  # (rank 0 only) after a failed write, say so without hiding that failure
                log.warning("could not write the index %s: %s", writer.xdmf_path, write_error_text(error))

    def write_output(self) -> None:
        """Collective: one history row and one step of every field series (once per step)."""
        sim = self.sim
        if self._last_output_step == sim.step_count:
            return
        self._last_output_step = sim.step_count
        row = sim.history_row()  # collective (sums over ranks): outside the write guard
        failure = None
        try:
            if self._history is not None:
                self._history.write(row)
        except OSError as error:  # rank 0 only: agreed on below, so no rank waits alone
            failure = write_error_text(error)
        self._raise_write_failure(failure, "history.csv")
        for label, write in self._field_writers():
            failure = None
            try:
                write()
            except (OSError, RuntimeError) as error:  # disk full, quota, I/O error (h5py)
                failure = write_error_text(error)
            self._raise_write_failure(failure, label)

    def _field_writers(self):
        sim = self.sim
        if self._particles_out is not None:
            yield "particles.h5", lambda: self._particles_out.write(sim.time, sim.step_count,
                                                                    self.particle_output_arrays())
        if self._clumps_out is not None:
            yield "clumps.h5", lambda: self._clumps_out.write(sim.time, sim.step_count, self.clump_output_arrays())
        for name, writer in self._solid_outputs.items():
            def write(name=name, writer=writer):
                point_data, cell_data = self.solid_output_arrays(name)
                writer.write(sim.time, sim.step_count, point_data, cell_data)
            yield f"{name}.h5", write

    def _raise_write_failure(self, failure, label: str) -> None:
        """Collective: an OutputError on every rank when any rank failed to write."""
        failure = agree_on_error(self.comm, failure)
        if failure is not None:
            if self.last_checkpoint is not None:
                carry_on = f"continue from the last checkpoint ({self.last_checkpoint[1]}) with --restart"
            elif self.sim.scene.checkpoint.every:
                carry_on = "run again: the run wrote no checkpoint before the failure"
            else:
                carry_on = "run again (with checkpoint.every set, a long run can continue from its last checkpoint)"
            raise OutputError(str(self.sim.output_dir / label),
                              f"cannot write the output ({failure}) at step {self.sim.step_count}",
                              f"free disk space (or write elsewhere with -o DIR); {carry_on}")

    def particle_output_arrays(self) -> dict:
        state = self.sim.particle_system.state
        owned = state.owned_count
        return {name: getattr(state, PARTICLE_SOURCES[name])[:owned] for name in self.particle_fields()}

    def clump_output_arrays(self) -> dict:
        """The clumps' series (clumps.h5): centre of mass, orientation (w, x, y, z: clump frame -> world),
        velocity, angular velocity and id of every body."""
        clumps = self.sim.clumps
        return {"positions": clumps.positions, "orientations": clumps.orientations, "velocities": clumps.velocities,
                "angular_velocities": clumps.angular_velocities, "ids": clumps.ids}

    def solid_output_arrays(self, name: str) -> tuple[dict, dict]:
        """(point data, cell data) of a solid as written: this rank's blocks of the output
        vertices and cells (input order, see _SolidOutputLayout)."""
        solid, layout = self.sim.solids[name], self._solid_layouts[name]
        wanted = self.sim.scene.output.solids
        nodal = {}
        # With motion: what a viewer sees (the frame's rigid motion included), and the elastic part apart.
        if "displacements" in wanted:
            nodal["displacements"] = solid.world_displacements
            if solid.frame is not None:
                nodal["elastic_displacements"] = solid.displacements
        if "velocities" in wanted:
            nodal["velocities"] = solid.world_velocities
        # Only where it says something: a solid that conducts, or one given a temperature (its thermal strain); the
        # others carried a field of 293.15 K at every node and step.
        if "temperature" in wanted and (solid.heat is not None or solid.config.temperatures()[0] is not None):
            nodal["temperature"] = solid.temperatures
        cells = {"von_mises": solid.von_mises} if "von_mises" in wanted else {}
        return layout.node_rows(nodal), layout.cell_rows(cells)

    # ============================================================== checkpoints
    def components(self) -> dict:
        """Every piece of state a checkpoint holds, by name, in the order a restart loads it: the
        solids, their coupled surfaces (mirroring the loaded solid) and the coupling, the walls,
        then the particles.  Each owns its state (pdemfem.state_dict.StateComponent)."""
        sim = self.sim
        components = {f"solid:{name}": solid for name, solid in sim.solids.items()}
        components.update({f"coupled_surface:{surface.name}": surface for surface in sim.coupled_surfaces})
        components["coupling"] = sim.coupling
        components["plane_walls"] = sim.particle_system.walls
        components.update({f"wall:{wall.name}": wall for wall in sim.contributor_walls})
        components.update({name: component for name, component in (("streams", sim.streams), ("outlets", sim.outlets))
                           if component is not None})
        components["particles"] = sim.particle_system
        components[OPTIONAL_COMPONENT] = sim.surface_force_means
        return components

    def write_checkpoint(self, diverged: bool = False) -> Path:
        """Collective: write a checkpoint of the current step, then put the simulation into the
        canonical state a restart from it starts with (see the module docstring).

        diverged: the state of a run the monitor stopped, kept for inspection as
        checkpoint_<step>_diverged.h5: latest.h5 keeps pointing at the last checkpoint before it and
        pruning (checkpoint.keep) leaves the earlier ones alone, so a restart from latest.h5 after the fix
        does not start from the broken state, and the good checkpoints are not pushed out by it."""
        sim, comm = self.sim, self.comm
        if self.last_checkpoint is not None and self.last_checkpoint[0] == sim.step_count and not diverged:
            return self.last_checkpoint[1]
        self._prepare_output()
        state = {name: component.state_dict() for name, component in self.components().items()}
        attributes = {
            "step": int(sim.step_count), "time": float(sim.time), "dt": float(sim.dt),
            "scene_hash": scene_hash(sim.scene),
            "scene_physics": scene_physics(sim.scene),  # so a hash mismatch can name the changed keys
            "rng_state": {"note": "particles are inserted from the scene's seeds (a stream's event from its seed "
                                  "and the event index): no random state is carried"},
            "insertion": {"complete": sim.streams is None, "inserted": int(sim.inserted_count)},
            "solids": list(sim.solids),
            "input_files": sim.input_digests,
        }
        directory = checkpoint_directory(sim)
        path = ckpt.checkpoint_path(directory, sim.step_count)
        if diverged:
            path = path.with_name(f"{path.stem}{ckpt.DIVERGED_SUFFIX}.h5")
        path = ckpt.write_state(path, comm, state, attributes=attributes,
                                keep=None if diverged else sim.scene.checkpoint.keep, written=self.written_checkpoints)
        if diverged:
            return path
        self.canonicalize()
        self.last_checkpoint = (sim.step_count, path)
        return path

    # ================================================================= canonical
    def canonicalize(self) -> None:
        """Collective: the state a restart from this step starts from (module docstring)."""
        for component in self.components().values():
            component.canonicalize()

    # =================================================================== restart
    def restore(self, path, force: bool = False) -> None:
        """Collective: continue from a checkpoint (any rank count); raises CheckpointError."""
        sim, comm = self.sim, self.comm
        # Read whatever the scene: what no --force and no edit of time.end or dt can fix (another scene's particles
        # or solids) is named before the physics change that --force would accept.
        checkpoint, state = ckpt.read_state(path, comm, expected_hash=None)
        attributes = checkpoint.attributes
        where = str(checkpoint.path)
        step = int(attributes["step"])
        changes = self._changes(attributes)
        self._refuse_other_particles(where, attributes, changes, force)
        if sorted(attributes.get("solids", [])) != sorted(sim.solids):
            raise CheckpointError(where, f"holds solids {attributes.get('solids')}, the scene has {list(sim.solids)}",
                                  "restart with the scene that wrote the checkpoint")
        refusal = ckpt.physics_refusal(attributes, scene_hash(sim.scene), force, scene_physics(sim.scene))
        if refusal is not None:
            raise CheckpointError(where, *refusal)
        total_steps = steps_to_end(sim.scene.time.end, sim.dt)  # as Simulation.run
        if step >= total_steps:
            raise CheckpointError(where, f"was written at step {step} (t = {step * sim.dt:.6g} s), at or past "
                                         f"time.end = {sim.scene.time.end:g} s ({total_steps} steps): there is "
                                         f"nothing left to run",
                                  "raise time.end in the scene to continue (time.end may change on a restart "
                                  "without --force)")
        if abs(float(attributes.get("dt", sim.dt)) - sim.dt) > 1e-12 * sim.dt:
            stored = float(attributes["dt"])
            given = ("dt: auto gives" if sim.scene.time.dt == "auto" else "time.dt is")
            raise CheckpointError(
                where, f"written with dt = {stored!r} s, and this scene's {given} {sim.dt!r} s: the time step is "
                       f"part of the stored state (step counts, velocities at half steps), so a restart keeps it",
                f"set time.dt: {stored!r} in the scene (the checkpoint's step, exactly; with --force, since time.dt "
                f"is physics), or start afresh without --restart")
        self._refuse_changed_input_files(where, attributes, force)
        self._refuse_replacing_other_physics(step)
        fix = "restart with the scene (walls, solids) that wrote the checkpoint"
        components = self.components()
        if OPTIONAL_COMPONENT not in state:  # an older version's checkpoint: the first row averages from the restart
            components.pop(OPTIONAL_COMPONENT)
        missing = [name for name in components if name not in state]
        if missing:
            raise CheckpointError(where, f"lacks the state of {', '.join(missing)} (in this scene)", fix)
        self._refuse_moved_walls(where, attributes, changes)
        for name, component in components.items():
            try:
                component.load_state_dict(state[name])
            except StateMismatch as mismatch:  # the same on every rank: the entries it checks are global
                raise CheckpointError(where, str(mismatch), fix) from None
        sim.step_count = step
        sim.time = sim.step_count * sim.dt
        self.canonicalize()
        self.restarted_from = checkpoint.path
        self.resume_step = sim.step_count
        self.last_checkpoint = (sim.step_count, checkpoint.path)


    def _refuse_other_particles(self, where: str, attributes: dict, all_changes: list, force: bool) -> None:
        """A restart continues the checkpoint's particles as stored: a scene that inserts another number of
        particles at t = 0 is refused even with --force (the stored state's shape changed, docs/output.md);
        other changes of the insertion (region, seed, radii with the same count) are warned to have no effect."""
        sim = self.sim
        changes = [text for text in all_changes if text.startswith("particles")]
        inserted = (attributes.get("insertion") or {}).get("inserted")
        if inserted is not None and int(inserted) != int(sim.inserted_count):
            listed = "; ".join(changes[:6]) if changes else "the particle groups"
            raise CheckpointError(
                where, f"holds the {int(inserted)} particles (spheres) its scene inserted at t = 0, this scene inserts "
                       f"{int(sim.inserted_count)} ({listed}): a restart continues the checkpoint's particles and "
                       f"cannot add or remove any, so it is refused even with --force",
                "restore the particle groups of the scene that wrote the checkpoint (their counts and insertion), "
                "or start afresh without --restart")
        streams = {f"particles[{index}]" for index, group in enumerate(sim.scene.particles)
                   if group.insert.kind == "stream"}
        schedule = [text for text in changes if text.split(".insert.")[0] in streams
                    and any(f".insert.{key}:" in text for key in ("rate", "mass_rate", "start"))]
        if schedule:
            # A stream inserts up to rate x (t - start) by time t: a new rate or start would apply from the stream's
            # start, and the stream would burst to catch up (or pause) after the restart.
            raise CheckpointError(
                where, f"changes a stream's schedule ({'; '.join(schedule[:4])}): a stream inserts rate x (t - start) "
                       f"particles by time t, so the change would apply from its start and the stream would burst "
                       f"or pause to catch up; refused even with --force",
                "keep the stream's rate, mass_rate and start, and add a second stream group for the new rate "
                "(starting at the restart's time), or start afresh without --restart")
        # What streams insert from now on takes the scene's region, velocity, radii and seed.
        stream_changes = [text for text in changes if text.split(".")[0] in streams]
        insertion_changes = [text for text in changes if text not in stream_changes and (
            ".insert." in text or ".radius" in text or ".clump" in text or ".initial_temperature" in text)]
        if force and stream_changes and self.comm.rank == 0:
            log.warning("restart: the streams insert their next particles as the scene now says: %s",
                        "; ".join(stream_changes[:6]))
        # The particles' masses and inertia are stored with them: a density change reaches the solids only.
        particle_materials = {group.material for group in sim.scene.particles}
        insertion_changes += [text for text in all_changes
                              if any(text.startswith(f"materials.{name}.density:") for name in particle_materials)]
        if force and insertion_changes and self.comm.rank == 0:
            log.warning("restart: the checkpoint's particles are continued as stored (positions, velocities, radii, "
                        "masses, temperatures); these changes of the scene take no effect on them: %s",
                        "; ".join(insertion_changes[:6]))

    def _refuse_changed_input_files(self, where: str, attributes: dict, force: bool) -> None:
        """A file the scene names (a solid's mesh, a mesh wall, a clump shape) whose content changed since the
        checkpoint was written is physics the scene hash cannot see: refused as a changed key is, and a mesh wall's
        even with --force (its vertices are stored state, as every wall's position).  Checkpoints written before
        the files were recorded are not checked."""
        stored = attributes.get("input_files")
        if not isinstance(stored, dict):
            return
        current = self.sim.input_digests
        # Files of one scene only (a solid or wall added or removed) are a change of the scene's structure, which the
        # structure checks name: "changed since" would mislead there.
        changed = sorted(key for key in set(stored) & set(current) if stored[key] != current[key])
        if not changed:
            return
        walls = [key for key in changed if key.startswith("walls")]
        named = input_files(self.sim.scene)
        listed = ", ".join(f"{key} ({named.get(key, '?')})" for key in changed[:4])
        if walls or not force:
            raise CheckpointError(
                where, f"was written with other contents of {listed}{' ...' if len(changed) > 4 else ''}: the "
                       f"file changed since (its sha256 differs)" + (", and a mesh wall's vertices are stored state, "
                                                                     "so it is refused even with --force" if walls else ""),
                "restore the file the checkpoint's run read, or start afresh without --restart" + (
                    "" if walls else "; --force continues with the new file (the solid's stored displacements "
                                     "are then applied to the new mesh's nodes)"))
        if self.comm.rank == 0:
            log.warning("restart: %s changed since the checkpoint was written; continuing with the new file (--force)",
                        listed)

    def _refuse_replacing_other_physics(self, step: int) -> None:
        """A restart writes its checkpoints under the names of their steps, so it replaces the checkpoints of later
        steps in its checkpoint directory.  Those of the same physics it writes again bit for bit (a restart
        continues exactly); those of other physics (a --force branch beside the run it started from) would be lost:
        refused, as a fresh run is refused a directory holding checkpoints it did not write."""
        refusal = None
        if self.comm.rank == 0:
            import h5py

            directory = checkpoint_directory(self.sim)
            expected = scene_hash(self.sim.scene)
            others = []
            for path in sorted(directory.glob(f"{ckpt.PREFIX}*.h5")):
                try:
                    later = int(path.stem[len(ckpt.PREFIX):]) > step
                except ValueError:
                    continue
                if later:
                    try:
                        with h5py.File(path, "r") as handle:
                            stored = handle.attrs.get("scene_hash")
                    except OSError:
                        stored = None  # unreadable: not this run's to replace either
                    if stored != expected:
                        others.append(path.name)
            if others:
                refusal = (str(directory), f"holds checkpoints of later steps than the restart's ({', '.join(others[:4])}"
                                           f"{' and more' if len(others) > 4 else ''}) written with other physics: this "
                                           f"run would replace them, and a run never overwrites checkpoints it did not "
                                           f"write",
                           "give this run its own checkpoint directory (checkpoint.dir, or -o DIR with a relative "
                           "checkpoint.dir), or move those checkpoints away")
        if self.comm.size > 1:
            refusal = self.comm.bcast(refusal, root=0)
        if refusal is not None:
            raise OutputError(*refusal)

    def _changes(self, attributes: dict) -> list:
        """The scene's physics changes against the checkpoint's ('key: old -> new'); [] for a file without its scene."""
        stored_physics = attributes.get("scene_physics")
        if not isinstance(stored_physics, dict):
            return []
        from pdemfem.scene.loader import physics_changes

        return physics_changes(stored_physics, scene_physics(self.sim.scene), limit=1000)

    def _refuse_moved_walls(self, where: str, attributes: dict, changes: list) -> None:
        """The walls' positions and motion are stored state (a moving wall's point is where its motion took it),
        restored by each wall's place in the list: a scene whose walls were moved, turned, reordered, added or
        removed is refused even with --force.  Their materials, temperatures and belt speeds come from the scene."""
        taken_from_scene = (".material:", ".temperature:", ".transport_velocity")
        changed = [text for text in changes
                   if text.startswith("walls") and not any(key in text for key in taken_from_scene)]
        stored_walls = (attributes.get("scene_physics") or {}).get("walls")
        if isinstance(stored_walls, list) and len(stored_walls) != len(self.sim.scene.walls):
            names = [wall.get("name") if isinstance(wall, dict) else "?" for wall in stored_walls]
            changed = [f"walls {names} -> {[wall.name for wall in self.sim.scene.walls]}"]
        if changed:
            raise CheckpointError(
                where, f"was written with other walls ({'; '.join(changed[:4])}"
                       f"{'; ...' if len(changed) > 4 else ''}): a restart continues the walls' stored positions "
                       f"and motion, so it is refused even with --force",
                "restore the walls (their order, geometry and motion) of the scene that wrote the checkpoint, or start "
                "afresh without --restart; a wall's material, temperature and transport_velocity may change")


# ====================================================================== helpers


# The history rows' interval means of the surface forces: a checkpoint of an older version lacks them.
OPTIONAL_COMPONENT = "surface_force_means"


def _truncate_history(path: Path, step: int, columns: list) -> tuple:
    """Keep the header and the rows up to `step` (a restart continues the table): (whether a row of `step` is
    among them, the columns the continued table has).

    A column the run now writes and the file lacks (a newer version's, or a scene changed with --force) is added,
    `nan` in the earlier rows; one the file has and the run no longer writes stays, `nan` in the new rows.  (The
    rows were appended under the old header: a reader put the extra field under no name.)"""
    if not path.exists():
        return False, columns
    with open(path, newline="") as handle:
        rows = list(csv.reader(handle))
    if not rows:
        return False, columns
    header, body = rows[0], rows[1:]
    column = header.index("step") if "step" in header else None
    # A row cut short by a kill mid-write (fewer fields than the header) is dropped, not parsed.
    kept = [row for row in body if len(row) == len(header) and (column is None or int(float(row[column])) <= step)]
    continued = list(columns) + [name for name in header if name not in columns]
    if continued != header:
        where = {name: index for index, name in enumerate(header)}
        kept = [[row[where[name]] if name in where else "nan" for name in continued] for row in kept]
    temporary = path.with_name(path.name + ".tmp")
    with open(temporary, "w", newline="") as handle:
        writer = csv.writer(handle)
        writer.writerow(continued)
        writer.writerows(kept)
    temporary.replace(path)
    return column is not None and bool(kept) and int(float(kept[-1][continued.index("step")])) == step, continued


class _SolidOutputLayout:
    """How a solid is written: its corner (P1) vertices and cells in the input mesh's numbering.

    The vertices are the tetrahedra's corner nodes (all nodes for P1, the corners for P2;
    the input numbers corners 0..n_corners-1 and midside nodes after them) and the cells
    the input cells, both stored in input order.  Rows are redistributed to that order
    with the id sort of checkpoint.py (one Alltoallv per field and output step), so the
    files do not depend on the rank count: a restart on another rank count continues the
    same series."""

    def __init__(self, solid, comm):
        from pdemfem.fem.assemble import ghosted_vector, local_values

        self.comm = comm
        mesh = solid.mesh
        owned = solid.n_owned_nodes
        numbers = ghosted_vector(comm, mesh, 1)  # input node numbers of owned and ghost nodes
        numbers.setArray(np.asarray(solid.original_node_ids, dtype=np.float64))
        local_ids = np.rint(local_values(numbers, 1)[:, 0]).astype(np.int64)
        numbers.destroy()
        is_corner = np.zeros(mesh.n_local_nodes, dtype=bool)
        is_corner[mesh.cells[:, :4].ravel()] = True
        self.nodes = np.flatnonzero(is_corner[:owned])
        self.node_keys = local_ids[self.nodes]
        self.cell_keys = np.asarray(solid.original_cell_ids, dtype=np.int64)
        keys, rows = ckpt.sort_rows_by_key(comm, self.node_keys, {"points": mesh.points[self.nodes]})
        self.points = rows["points"]
        self.node_offset = int(keys[0, 0]) if len(keys) else 0
        _, rows = ckpt.sort_rows_by_key(comm, self.cell_keys,
                                        {"cells": local_ids[mesh.cells[: mesh.n_owned_cells, :4]]})
        self.cells = rows["cells"]

    def node_rows(self, values: dict) -> dict:
        """Owned-node arrays (n_owned, ...) -> this rank's block of the output vertices."""
        picked = {name: np.asarray(array)[self.nodes] for name, array in values.items()}
        return ckpt.sort_rows_by_key(self.comm, self.node_keys, picked)[1] if picked else {}

    def cell_rows(self, values: dict) -> dict:
        return ckpt.sort_rows_by_key(self.comm, self.cell_keys, values)[1] if values else {}

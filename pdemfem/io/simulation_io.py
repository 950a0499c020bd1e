"""The Simulation's output, checkpoint and restart glue (keeps simulation.py thin).

    io = SimulationIO(simulation)                   # after the Simulation is built
    io.restore(path, force)                         # restart: load a checkpoint into it
    io.open()                                       # history.csv, particles.h5/.xdmf, <solid>.h5/.xdmf
    io.write_output()                               # every output interval (collective)
    io.write_checkpoint()                           # every checkpoint interval, at a stop, at the end
    io.close()

Exact continuation.  A checkpoint is taken at the end of a step; right
after writing it the running simulation puts itself into the *canonical* state a
restart rebuilds from the file (`canonicalize`):

- the particle system migrates, re-sorts (cell, then id) and rebuilds its lists with
  the decomposition kept (ParticleSystem.canonical_rebuild), carrying the last step's
  forces and torques (velocity Verlet's first half kick of the next step needs them;
  recomputing them would update the tangential springs and the dissipation twice, and
  the half-step velocities they were computed with are not stored);
- triangle surfaces rebuild their BVH from the current vertices and drop their
  candidate lists;
- the coupling's counter-forces accumulated since the last FE advance (sub-cycling,
  rank-local partial sums) are summed over the ranks onto rank 0 before they are written.

A restart builds the scene as usual, then overwrites every piece of state with the
file's and calls the same `canonicalize`, so on the same rank count (decomposition
restored from the file) the two runs sum every force in the same order: bit-identical.
On another rank count the particles are re-partitioned (RCB) and the FE vectors,
stored in the input mesh's node numbering, are read back by original node id; the
continuation then agrees to round-off.
"""
from __future__ import annotations

import csv
import json
import logging
import math
from pathlib import Path

import numpy as np
from mpi4py import MPI

from pdemfem.errors import CheckpointError, OutputError
from pdemfem.io import checkpoint as ckpt
from pdemfem.io.history import HistoryWriter
from pdemfem.io.output_guard import agree_on_error, prepare_output, write_error_text
from pdemfem.scene.loader import resolve_path, scene_hash, scene_physics

log = logging.getLogger("pdemfem")

FIELD_PREFIX = "field:"          # per-particle fields registered by contributors (state.fields)
SOLID_VECTORS = ("u", "v", "a", "internal", "load")  # per solid, 3 per node; plus T (1 per node)

# Particle output field -> ParticleState attribute.
PARTICLE_SOURCES = {"positions": "positions", "velocities": "velocities", "radii": "radii", "ids": "ids",
                    "forces": "forces", "temperature": "temperatures", "angular_velocities": "angular_velocities",
                    "torques": "torques", "materials": "material_index"}


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
        if comm.rank == 0 and append and self.resume_step is not None:
            _truncate_history(history_path, self.resume_step)
        comm.Barrier()
        self._history = HistoryWriter(history_path, columns, comm.rank == 0, append=append)
        output = sim.scene.output
        if output.particles:
            self._particles_out = ParticleOutput(sim.output_dir, comm, list(output.particles),
                                                 resume_step=self.resume_step)
        if output.solids:
            for name, solid in sim.solids.items():
                layout = self._solid_layouts[name] = _SolidOutputLayout(solid, comm)
                self._solid_outputs[name] = SolidOutput(sim.output_dir, name, comm, layout.points, layout.cells,
                                                        layout.node_offset, resume_step=self.resume_step)

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
        self._particles_out = None
        self._solid_outputs = {}

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
        for name, writer in self._solid_outputs.items():
            def write(name=name, writer=writer):
                point_data, cell_data = self.solid_output_arrays(name)
                writer.write(sim.time, sim.step_count, point_data, cell_data)
            yield f"{name}.h5", write

    def _raise_write_failure(self, failure, label: str) -> None:
        """Collective: an OutputError on every rank when any rank failed to write."""
        failure = agree_on_error(self.comm, failure)
        if failure is not None:
            raise OutputError(str(self.sim.output_dir / label),
                              f"cannot write the output ({failure}) at step {self.sim.step_count}",
                              "free disk space (or write elsewhere with -o DIR); continue from the latest "
                              "checkpoint with --restart")

    def particle_output_arrays(self) -> dict:
        state = self.sim.particle_system.state
        owned = state.owned_count
        return {name: getattr(state, PARTICLE_SOURCES[name])[:owned] for name in self.sim.scene.output.particles}

    def solid_output_arrays(self, name: str) -> tuple[dict, dict]:
        """(point data, cell data) of a solid as written: this rank's blocks of the output
        vertices and cells (input order, see _SolidOutputLayout)."""
        solid, layout = self.sim.solids[name], self._solid_layouts[name]
        wanted = self.sim.scene.output.solids
        nodal = {}
        if "displacements" in wanted:
            nodal["displacements"] = solid.displacements
        if "velocities" in wanted:
            nodal["velocities"] = solid.velocities
        if "temperature" in wanted:
            nodal["temperature"] = solid.temperatures
        cells = {"von_mises": solid.von_mises} if "von_mises" in wanted else {}
        return layout.node_rows(nodal), layout.cell_rows(cells)

    # ============================================================== checkpoints
    def write_checkpoint(self) -> Path:
        """Collective: write a checkpoint of the current step, then put the simulation into the
        canonical state a restart from it starts with (see the module docstring)."""
        sim, comm = self.sim, self.comm
        if self.last_checkpoint is not None and self.last_checkpoint[0] == sim.step_count:
            return self.last_checkpoint[1]
        self._prepare_output()
        self._sum_coupling_accumulators()
        system = sim.particle_system
        state = system.state
        owned = state.owned_count
        layout, _ = state.migrating_layout()
        particles = {}
        for name, *_ in layout:
            values = state.fields[name] if name in state.fields else getattr(state, name)
            key = FIELD_PREFIX + name if name in state.fields else name
            particles[key] = values[:owned]
        particles["forces"] = state.forces[:owned]
        particles["torques"] = state.torques[:owned]
        records = system.neighbors.contact_records(state.ids, owned)
        contacts = {"pairs": np.ascontiguousarray(records[:, :2]).astype(np.int64),
                    "shear": np.ascontiguousarray(records[:, 2:])}
        globals_, scalars = self._global_state()
        slabs = self._solid_slabs()
        attributes = {
            "step": int(sim.step_count), "time": float(sim.time), "dt": float(sim.dt),
            "scene_hash": scene_hash(sim.scene), "scalars": scalars,
            "scene_physics": scene_physics(sim.scene),  # so a hash mismatch can name the changed keys
            "rng_state": {"note": "all particles are inserted at t = 0 from the scene's seeds; no random "
                                  "numbers are drawn later"},
            "insertion": {"complete": True, "inserted": int(sim.inserted_count)},
            "particle_fields": [name for name in particles],
            "solids": list(sim.solids),
        }
        directory = checkpoint_directory(sim)
        path = ckpt.write_checkpoint(ckpt.checkpoint_path(directory, sim.step_count), comm,
                                     particle_arrays=particles, global_arrays=globals_, attributes=attributes,
                                     slab_arrays=slabs, contact_arrays=contacts, keep=sim.scene.checkpoint.keep,
                                     written=self.written_checkpoints)
        self.canonicalize()
        self.last_checkpoint = (sim.step_count, path)
        return path

    def _sum_coupling_accumulators(self) -> None:
        """Counter-forces accumulated since the last FE advance: summed over ranks onto rank 0."""
        driver = self.sim.coupling
        if not self.sim.solids or driver.steps_since_advance == 0:
            return
        for surface in self.sim.coupled_surfaces:
            total = surface.accumulated_forces.copy()
            if self.comm.size > 1:
                self.comm.Allreduce(MPI.IN_PLACE, total, op=MPI.SUM)
            surface.accumulated_forces[:] = total if self.comm.rank == 0 else 0.0
            # The window's contact dashpots likewise move to rank 0, as a restart has them.
            surface.restore_records(surface.checkpoint_records(self.comm), self.comm)

    def _global_state(self) -> tuple[dict, dict]:
        sim = self.sim
        system = sim.particle_system
        walls = system.walls
        arrays = {"plane_walls:points": walls.points, "plane_walls:velocities": walls.velocities,
                  "plane_walls:forces": walls.forces}
        scalars = {"dissipated_energy": system.dissipated_energy, "elastic_energy": system.elastic_energy,
                   "contact_count": int(system.contact_count), "lost_particles": int(system.lost_particles),
                   "rebalances": int(system.rebalances), "plane_wall_work": float(walls.work),
                   "contributors": {}, "solids": {},
                   "coupling": {"steps_since_advance": int(sim.coupling.steps_since_advance),
                                "advances": int(getattr(sim.coupling, "advances", 0)),
                                "fem_substeps": dict(sim.coupling.fem_substeps)}}
        for wall in sim.contributor_walls:
            entry = {"work": float(wall.work)}
            if hasattr(wall, "time"):
                entry["time"] = float(wall.time)
            scalars["contributors"][wall.name] = entry
            for attribute in ("vertices", "vertex_velocities", "totals", "point", "direction"):
                if hasattr(wall, attribute):
                    arrays[f"contributor:{wall.name}:{attribute}"] = np.asarray(getattr(wall, attribute))
        for surface in sim.coupled_surfaces:
            total = surface.accumulated_forces.copy()  # rank 0 holds the sum, the others zeros: exact
            if self.comm.size > 1:
                self.comm.Allreduce(MPI.IN_PLACE, total, op=MPI.SUM)
            arrays[f"coupling:{surface.name}:accumulated_forces"] = total
            arrays[f"coupling:{surface.name}:damper_records"] = surface.checkpoint_records(self.comm)
        if sim.solids:
            scalars["coupling"]["dashpot_dissipation"] = sim.dashpot_dissipation()
        for name, solid in sim.solids.items():
            scalars["solids"][name] = {"time": float(solid.time), "step_count": int(solid.step_count),
                                       "external_work": float(solid.external_work)}
        decomposition = system.decomposition
        if decomposition is not None:
            for attribute in ("boxes", "node_axis", "node_cut", "node_left", "node_right"):
                arrays[f"decomposition:{attribute}"] = np.asarray(getattr(decomposition, attribute))
        return {name: np.ascontiguousarray(values) for name, values in arrays.items()}, scalars

    def _solid_slabs(self) -> dict:
        """FE vectors by original (input mesh) node number: identical for any rank count."""
        slabs = {}
        for name, solid in self.sim.solids.items():
            vectors = {"u": solid.displacement_vec, "v": solid.velocity_vec, "a": solid.acceleration_vec,
                       "internal": solid.internal_force_vec, "load": solid.load_vec}
            rows = {key: vec.getArray(readonly=True).reshape(-1, 3).copy() for key, vec in vectors.items()}
            rows["T"] = solid.temperature_vec.getArray(readonly=True).copy()
            keys, rows = ckpt.sort_rows_by_key(self.comm, np.asarray(solid.original_node_ids, dtype=np.int64), rows)
            keys = keys[:, 0] if keys.ndim == 2 else keys
            first = int(keys[0]) if len(keys) else 0
            if len(keys) and int(keys[-1]) - first + 1 != len(keys):
                raise RuntimeError(f"solid {name}: original node numbers are not contiguous")
            for key, values in rows.items():
                slabs[f"solid:{name}:{key}"] = (values, first)
        return slabs

    # ================================================================= canonical
    def canonicalize(self, records=None, decomposition=None) -> None:
        """Collective: the state a restart from this step starts from (module docstring)."""
        sim = self.sim
        for wall in sim.contributor_walls:
            if hasattr(wall, "bvh"):
                wall.bvh.build(wall.vertices)
                wall._bvh_current = True
                wall._list_key = None
        sim.particle_system.canonical_rebuild(records=records, decomposition=decomposition)

    # =================================================================== restart
    def restore(self, path, force: bool = False) -> None:
        """Collective: continue from a checkpoint (any rank count); raises CheckpointError."""
        sim, comm = self.sim, self.comm
        checkpoint = ckpt.read_checkpoint(path, comm, expected_hash=scene_hash(sim.scene), force=force,
                                          expected_physics=scene_physics(sim.scene))
        attributes = checkpoint.attributes
        where = str(checkpoint.path)
        step = int(attributes["step"])
        total_steps = int(math.ceil(sim.scene.time.end / sim.dt - 1e-9))  # as Simulation.run
        if step >= total_steps:
            raise CheckpointError(where, f"was written at step {step} (t = {step * sim.dt:.6g} s), at or past "
                                         f"time.end = {sim.scene.time.end:g} s ({total_steps} steps): there is "
                                         f"nothing left to run",
                                  "raise time.end in the scene to continue (time.end may change on a restart "
                                  "without --force)")
        if abs(float(attributes.get("dt", sim.dt)) - sim.dt) > 1e-12 * sim.dt:
            raise CheckpointError(where, f"written with dt = {attributes['dt']:g} s, this scene has dt = {sim.dt:g} s",
                                  "restart with the scene's original time step")
        if sorted(attributes.get("solids", [])) != sorted(sim.solids):
            raise CheckpointError(where, f"holds solids {attributes.get('solids')}, the scene has {list(sim.solids)}",
                                  "restart with the scene that wrote the checkpoint")
        scalars = attributes["scalars"]
        self._restore_solids(checkpoint, scalars)
        self._restore_walls(checkpoint, scalars)
        records = self._restore_particles(checkpoint, scalars)
        decomposition = None
        system = sim.particle_system
        if int(attributes.get("ranks_at_write", -1)) == comm.size and "decomposition:boxes" in checkpoint.globals:
            from pdemfem.parallel.decomposition import Decomposition

            decomposition = Decomposition(*(checkpoint.globals[f"decomposition:{attribute}"]
                                            for attribute in ("boxes", "node_axis", "node_cut", "node_left",
                                                              "node_right")))
        else:
            system.decomposition = None  # re-partition the loaded particles (another rank count)
            system.ghosts = None
        sim.step_count = int(attributes["step"])
        sim.time = sim.step_count * sim.dt
        self.canonicalize(records=records, decomposition=decomposition)
        self.restarted_from = checkpoint.path
        self.resume_step = sim.step_count
        self.last_checkpoint = (sim.step_count, checkpoint.path)

    def _restore_solids(self, checkpoint, scalars) -> None:
        from petsc4py import PETSc

        sim = self.sim
        for name, solid in sim.solids.items():
            nodes = np.asarray(solid.original_node_ids, dtype=np.int64)
            slabs = {key: checkpoint.slabs[f"solid:{name}:{key}"] for key in SOLID_VECTORS + ("T",)}
            if len(slabs["u"]) != solid.n_global_nodes:
                raise CheckpointError(str(checkpoint.path),
                                      f"solid '{name}' has {len(slabs['u'])} nodes in the checkpoint, "
                                      f"{solid.n_global_nodes} in this scene's mesh",
                                      "restart with the mesh that wrote the checkpoint")
            targets = {"u": solid.displacement_vec, "v": solid.velocity_vec, "a": solid.acceleration_vec,
                       "internal": solid.internal_force_vec, "load": solid.load_vec}
            for key, vec in targets.items():
                vec.setArray(np.ascontiguousarray(slabs[key][nodes]).ravel())
            temperatures = slabs["T"][nodes]
            if not np.array_equal(temperatures, solid.temperatures):
                solid.set_temperature(temperatures)
            solid.displacement_vec.ghostUpdate(addv=PETSc.InsertMode.INSERT_VALUES, mode=PETSc.ScatterMode.FORWARD)
            entry = scalars["solids"][name]
            solid.time, solid.step_count = float(entry["time"]), int(entry["step_count"])
            solid.external_work = float(entry["external_work"])
        for surface in sim.coupled_surfaces:
            # Positions from the restored solid; the mirrored velocities (the mean over the last
            # advance, see coupling/driver.py) come back with the wall state (_restore_walls).
            surface.refresh_vertices()
            stored = checkpoint.globals[f"coupling:{surface.name}:accumulated_forces"]
            surface.accumulated_forces[:] = stored if self.comm.rank == 0 else 0.0
            surface.restore_records(checkpoint.globals[f"coupling:{surface.name}:damper_records"], self.comm)
            surface.dissipation_correction_local = 0.0
        coupling = scalars["coupling"]
        for solid in sim.solids.values():
            solid.damper_work_local = 0.0
        if sim.coupled_surfaces and self.comm.rank == 0:
            sim.coupled_surfaces[0].dissipation_correction_local = float(coupling["dashpot_dissipation"])
        sim.coupling.steps_since_advance = int(coupling["steps_since_advance"])
        sim.coupling.fem_substeps.update({k: int(v) for k, v in coupling["fem_substeps"].items()})
        if hasattr(sim.coupling, "advances"):
            sim.coupling.advances = int(coupling.get("advances", 0))

    def _restore_walls(self, checkpoint, scalars) -> None:
        sim = self.sim
        walls = sim.particle_system.walls
        for attribute in ("points", "velocities", "forces"):
            stored = checkpoint.globals[f"plane_walls:{attribute}"]
            if stored.shape != getattr(walls, attribute).shape:
                raise CheckpointError(str(checkpoint.path), "the scene's plane walls differ from the checkpoint's",
                                      "restart with the scene that wrote the checkpoint")
            getattr(walls, attribute)[...] = stored
        walls.work = float(scalars["plane_wall_work"])
        for wall in sim.contributor_walls:
            entry = scalars["contributors"].get(wall.name)
            if entry is None:
                raise CheckpointError(str(checkpoint.path), f"wall '{wall.name}' is not in the checkpoint",
                                      "restart with the scene that wrote the checkpoint")
            wall.work = float(entry["work"])
            if "time" in entry:
                wall.time = float(entry["time"])
            stored = {attribute: checkpoint.globals[f"contributor:{wall.name}:{attribute}"]
                      for attribute in ("vertices", "vertex_velocities", "totals", "point", "direction")
                      if f"contributor:{wall.name}:{attribute}" in checkpoint.globals}
            if "vertices" in stored:
                wall.set_vertices(stored.pop("vertices"), stored.pop("vertex_velocities", None))
            for attribute, values in stored.items():
                setattr(wall, attribute, np.array(values))

    def _restore_particles(self, checkpoint, scalars) -> np.ndarray:
        """Replace the particle state by this rank's share of the checkpoint's; return the contact
        records routed to the ranks holding their owner particle."""
        from pdemfem.neighbors.verlet import VerletList
        from pdemfem.particles.state import MIGRATING_FIELDS, ParticleState

        sim, comm = self.sim, self.comm
        system = sim.particle_system
        old = system.state
        arrays = checkpoint.particles
        expected = set(MIGRATING_FIELDS) | {FIELD_PREFIX + name for name in old.fields} | {"forces", "torques"}
        missing = sorted(expected - set(arrays))
        if missing and checkpoint.particle_count:
            raise CheckpointError(str(checkpoint.path), f"lacks the per-particle state {missing} this scene needs",
                                  "restart with the scene (walls, solids) that wrote the checkpoint")
        count = len(arrays.get("ids", ()))
        state = ParticleState(
            ids=arrays["ids"] if count else np.zeros(0, np.int64),
            material_index=arrays["material_index"] if count else np.zeros(0, np.int32),
            radii=arrays["radii"] if count else np.zeros(0), densities=np.ones(count),
            positions=arrays["positions"] if count else np.zeros((0, 3)),
            velocities=arrays["velocities"] if count else np.zeros((0, 3)),
            angular_velocities=arrays["angular_velocities"] if count else np.zeros((0, 3)),
            temperatures=arrays["temperatures"] if count else np.zeros(0),
            wall_count=system.walls.count, history_width=system.tables.history_width)
        for name in ("mass", "inverse_mass", "inverse_inertia", "wall_history", "forces", "torques"):
            if count:
                setattr(state, name, np.ascontiguousarray(arrays[name], dtype=getattr(state, name).dtype))
        for key, values in arrays.items():
            if key.startswith(FIELD_PREFIX):
                state.fields[key[len(FIELD_PREFIX):]] = np.ascontiguousarray(values)
        for name, values in old.fields.items():  # a field absent from an empty share
            if name not in state.fields:
                state.fields[name] = np.zeros((count, *values.shape[1:]), dtype=values.dtype)
        state.positions_at_build = state.positions.copy()
        system.state = state
        system.neighbors = VerletList()
        system.dissipated_energy = float(scalars["dissipated_energy"])
        system.elastic_energy = float(scalars["elastic_energy"])
        system.contact_count = int(scalars["contact_count"])
        system.lost_particles = int(scalars["lost_particles"])
        system.rebalances = int(scalars["rebalances"])
        pairs = checkpoint.contacts.get("pairs", np.zeros((0, 2), np.int64))
        shear = checkpoint.contacts.get("shear", np.zeros((0, 3)))
        records = np.column_stack([pairs.astype(np.float64), shear]) if len(pairs) else np.zeros((0, 5))
        if comm.size > 1:
            records = _route_to_owner_share(comm, state.ids, records)
        return records


# ====================================================================== helpers


def _route_to_owner_share(comm, ids: np.ndarray, records: np.ndarray) -> np.ndarray:
    """Send each record to the rank whose (id-sorted, contiguous) share holds its owner id."""
    from pdemfem.parallel.exchange import _alltoallv_rows

    first_ids = np.array(comm.allgather(int(ids[0]) if len(ids) else None), dtype=object)
    ranks = np.array([r for r, value in enumerate(first_ids) if value is not None], dtype=np.int64)
    starts = np.array([first_ids[r] for r in ranks], dtype=np.int64)
    owners = records[:, 0].astype(np.int64) if len(records) else np.zeros(0, np.int64)
    if len(ranks) == 0:
        destinations = np.zeros(len(owners), dtype=np.int64)
    else:
        destinations = ranks[np.maximum(np.searchsorted(starts, owners, side="right") - 1, 0)]
    return _alltoallv_rows(comm, np.ascontiguousarray(records, dtype=np.float64), destinations, records.shape[1])


def _truncate_history(path: Path, step: int) -> None:
    """Keep the header and the rows up to `step` (a restart continues the table)."""
    if not path.exists():
        return
    with open(path, newline="") as handle:
        rows = list(csv.reader(handle))
    if not rows:
        return
    header, body = rows[0], rows[1:]
    column = header.index("step") if "step" in header else None
    kept = [row for row in body if column is None or (len(row) > column and int(float(row[column])) <= step)]
    temporary = path.with_name(path.name + ".tmp")
    with open(temporary, "w", newline="") as handle:
        writer = csv.writer(handle)
        writer.writerow(header)
        writer.writerows(kept)
    temporary.replace(path)


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

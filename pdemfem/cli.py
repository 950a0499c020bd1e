"""The `pdemfem` command.

    pdemfem run scene.yaml [-o DIR] [--quiet] [--restart FILE] [--force] [-fem_<option> [value] ...]
        (-fem_* arguments go to PETSc's options database: the FE solvers' prefixes fem_ and fem_mass_)
    pdemfem check scene.yaml [--strict]     (reads and checks everything `run` reads before its first step)
    pdemfem info
    pdemfem plot OUTDIR [--quiet]
    pdemfem render OUTDIR [--scene scene.yaml] [-o picture.png] [--renderer auto|paraview|matplotlib]
                   [--pvpython PATH] [--quiet]          (the run's last output step)
    pdemfem render --gallery [--runs DIR] [--renderer ...] [--quiet]   (runs every examples/*.yaml;
                                                         docs/img/gallery, docs/gallery.md)

Under MPI (``python -m pdemfem.launch -n 2 -- pdemfem run scene.yaml``) every rank
runs the same command.  Errors:

* a user error (`PdemfemError`: bad scene, mesh, checkpoint) is printed once, by
  rank 0, as ``error: <message>`` on stderr, and every rank exits with the
  error's exit code (2 for input errors) together -- no traceback.  Ranks
  synchronise on a non-blocking barrier; a rank whose error the others do not
  share within PDEMFEM_ERROR_SYNC_SECONDS (30 s) aborts the job instead of hanging.
* any other exception on several ranks prints its traceback with the rank and
  calls ``MPI.COMM_WORLD.Abort(1)``, so no rank waits forever.
* nothing is created on disk before the scene is validated and built; an output
  directory a failed `run` created during set-up is removed again.
* an output directory holding an earlier run's results is refused (exit 2) unless
  --force (start afresh) or --restart; checkpoints a run did not write are never
  deleted or overwritten (pdemfem.io.output_guard).
"""
from __future__ import annotations

import argparse
import inspect
import logging
import math
import os
import re
import shutil
import sys
import time
import traceback
from pathlib import Path
from typing import Callable, List, Optional

import pdemfem  # noqa: F401  (sets PETSC_DIR and the MPI environment before mpi4py/petsc4py load)
from pdemfem.errors import PdemfemError, SceneError

__all__ = ["main", "build_parser"]

ERROR_SYNC_SECONDS = float(os.environ.get("PDEMFEM_ERROR_SYNC_SECONDS", "30"))


class _LoggedToStderr(logging.Handler):
    """The package's run-time messages on stderr as `warning: ...` (as run prints check's warnings; a message
    that names its kind, `note: ...`, as it is).  Python's fallback printed them bare.  sys.stderr is looked up
    at each message, so a redirected stderr receives them."""

    def emit(self, record) -> None:
        try:
            text = self.format(record)
            if not text.startswith(("note:", "warning:", "error:")):
                text = f"{record.levelname.lower()}: {text}"
            print(text, file=sys.stderr, flush=True)
        except Exception:  # as logging's own handlers: a failing message never stops the run
            self.handleError(record)


def _log_to_stderr() -> None:
    logger = logging.getLogger("pdemfem")
    if not any(isinstance(handler, _LoggedToStderr) for handler in logger.handlers):
        handler = _LoggedToStderr(logging.WARNING)
        logger.addHandler(handler)


# --------------------------------------------------------------------------- parser


def _launcher_rank() -> int:
    """This process's rank from the launcher's environment (before MPI is initialised)."""
    for variable in ("OMPI_COMM_WORLD_RANK", "PMI_RANK", "PMIX_RANK", "MV2_COMM_WORLD_RANK", "SLURM_PROCID"):
        value = os.environ.get(variable)
        if value is not None and value.isdigit():
            return int(value)
    return 0


class _Parser(argparse.ArgumentParser):
    """argparse that prints usage errors once under MPI (every rank exits 2)."""

    def _print_message(self, message, file=None):
        if _launcher_rank() == 0:
            super()._print_message(message, file)


def build_parser() -> argparse.ArgumentParser:
    parser = _Parser(
        prog="pdemfem",
        description="MPI-parallel coupled DEM/FEM solver. Under MPI: python -m pdemfem.launch -n 2 -- pdemfem ...",
    )
    parser.add_argument("--version", action="version", version=f"pdemfem {pdemfem.__version__}")
    commands = parser.add_subparsers(dest="command", metavar="COMMAND", parser_class=_Parser)
    commands.required = True

    run = commands.add_parser("run", help="run a scene to time.end")
    run.add_argument("scene", help="scene file (YAML)")
    run.add_argument("-o", "--output", metavar="DIR", help="output directory (default: the scene's output.dir, "
                     "relative to the scene file)")
    run.add_argument("--quiet", action="store_true", help="no progress bar or summary")
    run.add_argument("--restart", metavar="FILE", help="continue from a checkpoint file (or a checkpoint "
                     "directory: its latest.h5), on any number of ranks")
    run.add_argument("--force", action="store_true", help="start afresh in an output directory holding an "
                     "earlier run's results (deletes them; checkpoints are never deleted); with --restart: accept "
                     "a checkpoint written for a scene whose physics changed (scene hash mismatch)")
    run.set_defaults(handler=_command_run)

    check = commands.add_parser("check", help="validate a scene and print derived quantities (dt, contact duration, memory)")
    check.add_argument("scene", help="scene file (YAML)")
    check.add_argument("--strict", action="store_true", help="exit 1 when there are warnings")
    check.set_defaults(handler=_command_check)

    info = commands.add_parser("info", help="versions of Python, numpy, numba, PETSc, MPI; rank count; parallel HDF5")
    info.set_defaults(handler=_command_info)

    plot = commands.add_parser("plot", help="plot OUTDIR/history.csv into OUTDIR/plots/*.png")
    plot.add_argument("outdir", help="a run's output directory")
    plot.add_argument("--quiet", action="store_true", help="do not list the files written")
    plot.set_defaults(handler=_command_plot)

    render = commands.add_parser("render", help="draw a run's last output step (particles, solids, walls) into a PNG")
    render.add_argument("outdir", nargs="?", help="a run's output directory")
    render.add_argument("--scene", metavar="FILE", help="the run's scene file: its walls are drawn too")
    render.add_argument("-o", "--output", metavar="PNG", help="the picture (default: OUTDIR/render.png)")
    render.add_argument("--gallery", action="store_true", help="run every examples/*.yaml and write "
                        "docs/img/gallery/<example>.png and docs/gallery.md")
    render.add_argument("--runs", metavar="DIR", default="out/gallery",
                        help="with --gallery: where the example runs write (default: out/gallery)")
    render.add_argument("--renderer", default="auto", help="auto (default: ParaView's pvpython when found, "
                        "else matplotlib), paraview or matplotlib")
    render.add_argument("--pvpython", metavar="PATH", help="ParaView's pvpython (default: $PDEMFEM_PVPYTHON, "
                        "then pvpython on PATH)")
    render.add_argument("--quiet", action="store_true", help="do not list the files written")
    render.set_defaults(handler=_command_render)
    return parser


# --------------------------------------------------------------------------- entry point


def main(argv: Optional[List[str]] = None) -> int:
    """Run the command line; returns the exit code (the console script exits with it)."""
    parser = build_parser()
    _log_to_stderr()
    arguments, unknown = parser.parse_known_args(argv)
    petsc_options, rest = split_petsc_options(unknown)
    if rest:
        parser.error(f"unrecognized arguments: {' '.join(rest)} (PETSc options must start with -fem_)")
    if petsc_options:
        if arguments.command != "run":
            parser.error(f"PETSc options ({' '.join(name for name, _ in petsc_options)}) only apply to run")
        _set_petsc_options(petsc_options)
    from mpi4py import MPI

    comm = MPI.COMM_WORLD
    arguments.petsc_options = petsc_options
    try:
        return int(arguments.handler(arguments, comm) or 0)
    except PdemfemError as error:
        return _fail_together(comm, error)
    except KeyboardInterrupt:
        if comm.size > 1:
            comm.Abort(130)
        print("interrupted", file=sys.stderr)
        return 130
    except Exception:
        if comm.size > 1:
            text = traceback.format_exc()
            sys.stderr.write("".join(f"[rank {comm.rank}] {line}\n" for line in text.rstrip().splitlines()))
            sys.stderr.flush()
            comm.Abort(1)
        raise


PETSC_OPTION_PREFIX = "-fem_"


def split_petsc_options(arguments: List[str]) -> tuple:
    """([(name, value or None)] of the -fem_* PETSc options, the other arguments).

    A value is the next argument unless that is another option (a negative number is a value)."""
    options, rest = [], []
    index = 0
    while index < len(arguments):
        argument = arguments[index]
        if argument.startswith(PETSC_OPTION_PREFIX):
            name, _, value = argument.partition("=")
            if not value and index + 1 < len(arguments) and not _is_option(arguments[index + 1]):
                value = arguments[index + 1]
                index += 1
            options.append((name, value or None))
        else:
            rest.append(argument)
        index += 1
    return options, rest


def _is_option(text: str) -> bool:
    if not text.startswith("-"):
        return False
    try:
        float(text)
        return False
    except ValueError:
        return True


def _set_petsc_options(options) -> None:
    """Put -fem_* options (the FE solvers' prefixes: -fem_static_*, -fem_mass_*) into PETSc's database."""
    from pdemfem.fem.petsc import PETSc

    database = PETSc.Options()
    for name, value in options:
        database.setValue(name[1:], value if value is not None else "")
    # PETSc's unused-options report at exit: a misspelt option (-fem_ksp_rtoll) or one no solver
    # of this scene reads is listed ("Option left: name:-fem_ksp_rtoll ...") instead of ignored.
    if not database.hasName("options_left"):
        database.setValue("options_left", "")


def _fail_together(comm, error: PdemfemError) -> int:
    """Report a user error once and return its exit code on every rank (or abort, never hang)."""
    cleanup = getattr(error, "cleanup_dir", None)
    if comm.size == 1:
        _remove_created_dir(cleanup)
        _print_error(str(error))
        return error.exit_code
    request = comm.Ibarrier()
    deadline = time.monotonic() + ERROR_SYNC_SECONDS
    while not request.Test():
        if time.monotonic() > deadline:
            _print_error(f"(rank {comm.rank} of {comm.size}; the other ranks did not fail with it) {error}")
            comm.Abort(error.exit_code)
        time.sleep(0.002)
    # Every rank holds a user error: rank 0 prints the distinct messages once.
    messages = comm.gather(str(error), root=0)
    codes = comm.allgather(error.exit_code)
    if comm.rank == 0:
        _remove_created_dir(cleanup)
        distinct = list(dict.fromkeys(messages))
        if len(distinct) == 1:
            _print_error(distinct[0])
        else:
            for rank, message in enumerate(messages):
                if message in distinct:
                    _print_error(f"(rank {rank}) {message}")
                    distinct.remove(message)
    return max(codes)


def _print_error(message: str) -> None:
    sys.stdout.flush()
    print(f"error: {message}", file=sys.stderr, flush=True)


def _remove_created_dir(path: Optional[Path]) -> None:
    if path is not None and path.is_dir():
        shutil.rmtree(path, ignore_errors=True)


def _on_root(comm, function: Callable[[], object]):
    """Run `function` on rank 0 only; every rank returns its result or raises its PdemfemError."""
    outcome = None
    if comm.rank == 0:
        try:
            outcome = ("ok", function())
        except PdemfemError as error:
            outcome = ("error", type(error).__name__, error.where, error.problem, error.fix, error.exit_code)
    if comm.size > 1:
        # Only plain data crosses ranks (never a pickled exception object).
        shared = comm.bcast(outcome if outcome is None or outcome[0] == "error" else ("ok", None), root=0)
        if comm.rank != 0:
            outcome = shared
    if outcome[0] == "error":
        _, _, where, problem, fix, code = outcome
        error = PdemfemError(where, problem, fix)
        error.exit_code = code
        raise error
    return outcome[1]


def _name_the_file(error: PdemfemError, path) -> PdemfemError:
    """A SceneError raised while building names only its key path; prefix the scene file."""
    from pdemfem.scene.loader import key_line

    label = str(path)
    if isinstance(error, SceneError) and not error.where.startswith(label):
        line = key_line(path, error.where)
        where = f"{label}: line {line}: {error.where}" if line is not None else f"{label}: {error.where}"
        located = SceneError(where, error.problem, error.fix)
        located.exit_code = error.exit_code
        return located
    return error


def _say(comm, text: str = "", quiet: bool = False) -> None:
    if comm.rank == 0 and not quiet:
        print(text, flush=True)


# --------------------------------------------------------------------------- run


def _command_run(arguments, comm) -> int:
    from pdemfem.scene import derived
    from pdemfem.scene.loader import load_scene, output_directory

    # Validate first: nothing may be created on disk for an invalid scene.
    scene, base_dir = load_scene(arguments.scene)
    output_dir = output_directory(scene, base_dir, arguments.output)
    existed = output_dir.exists()
    _refuse_earlier_results(scene, base_dir, output_dir, arguments, comm, existed)

    from pdemfem.simulation import Simulation

    options = {}
    if arguments.restart is not None:
        options["restart"] = arguments.restart
    if arguments.force:
        options["force"] = True
    accepted = inspect.signature(Simulation.from_file).parameters
    for name in options:
        if name not in accepted and not any(p.kind is p.VAR_KEYWORD for p in accepted.values()):
            raise PdemfemError(f"--{name}", "this version of pdemfem cannot do that yet",
                               f"run without --{name}")
    try:
        simulation = Simulation.from_file(arguments.scene, comm=comm, output_dir=arguments.output, **options)
    except Exception as error:
        if isinstance(error, PdemfemError):
            located = _name_the_file(error, arguments.scene)
        elif isinstance(error, OUT_OF_RANGE):
            located = _out_of_range(arguments.scene, error)
        elif arguments.petsc_options and type(error).__module__.startswith("petsc4py"):
            located = _refused_petsc_options(arguments.petsc_options, error)
        else:
            raise
        if not existed:
            located.cleanup_dir = output_dir
        raise located from None
    if not arguments.quiet:
        count = derived.particle_count(scene)
        dt = getattr(simulation, "dt", None) or derived.time_step(scene)
        streams = " (+ streams)" if any(group.insert.kind == "stream" for group in scene.particles) else ""
        _say(comm, f"pdemfem run {arguments.scene}: {count} particles{streams} on {comm.size} rank(s), "
                   f"dt = {dt:.3g} s, end = {scene.time.end:g} s, output: {output_dir}")
    # The warnings of `pdemfem check`, before the first step (stderr, also with --quiet).
    solid_step = simulation.dt if simulation.solids and not scene.particles else None
    found = derived.warnings(scene, solid_critical_step=solid_step, dt=simulation.dt)
    found += derived.mesh_wall_warnings(scene, simulation.contributor_walls) + simulation.coupling_warnings
    if comm.rank == 0:
        for warning in found:
            print(f"warning: {warning}", file=sys.stderr, flush=True)
    simulation.run(progress=not arguments.quiet)
    _say(comm, f"results: {output_dir}", arguments.quiet)
    return 0


def _refuse_earlier_results(scene, base_dir, output_dir, arguments, comm, existed: bool) -> None:
    """Before the (possibly long) build: an output directory holding an earlier run's results is
    refused unless --force or --restart, and both output directories must be writable.  The
    earlier files are deleted (with --force) only when the run starts writing."""
    from pdemfem.io.output_guard import prepare_output
    from pdemfem.io.simulation_io import checkpoint_directory_of

    try:
        prepare_output(output_dir, checkpoint_directory_of(scene, base_dir, output_dir), comm,
                       restart=arguments.restart is not None, force=arguments.force, clear=False)
    except PdemfemError as error:
        if not existed:
            error.cleanup_dir = output_dir
        raise


def _refused_petsc_options(petsc_options, error) -> PdemfemError:
    """PETSc refusing a -fem_* option's value (an unknown solver or preconditioner type) raises on every rank
    while the solids are set up: the option is the user's, so it is named, not traced back."""
    given = " ".join(name + (f" {value}" if value is not None else "") for name, value in petsc_options)
    # PETSc's message ends with its reason ("[0] Unable to find requested KSP type nonsense").
    reason = re.sub(r"^\[\d+\]\s*", "", str(error).strip().splitlines()[-1]).rstrip(")")
    return PdemfemError(f"PETSc options {given}", f"PETSc refused them: {reason}",
                        "check each option's name and value (docs/fem.md, 'Solver options' under 'Python API'), "
                        "e.g. -fem_ksp_type cg, -fem_pc_type gamg")


# --------------------------------------------------------------------------- check


def _format_bytes(value: float) -> str:
    for unit in ("B", "kB", "MB", "GB", "TB"):
        if value < 1000.0 or unit == "TB":
            return f"{value:.3g} {unit}"
        value /= 1000.0
    return f"{value:.3g} TB"


def check_report(path: str) -> tuple:
    """(lines, warnings) for `pdemfem check`; raises SceneError for an invalid scene.

    Reads everything a run reads before its first step (the insertion, the mesh-wall and
    solid mesh files) and applies the same checks, so overlapping list positions, regions
    that cannot hold their count or lie outside domain.box, broken meshes, periodic lengths
    below the cutoff and out-of-range coordinates are reported here too.
    """
    from pdemfem.scene.loader import load_scene

    scene, base_dir = load_scene(path)
    try:
        placed, solids, mesh_warnings = _validate_as_run(scene, base_dir)
    except SceneError as error:
        raise _name_the_file(error, path) from None
    try:
        return _report(path, scene, base_dir, placed, solids, mesh_warnings)
    except OUT_OF_RANGE as error:
        raise _out_of_range(path, error) from None


# The schema's bounds cannot catch every combination of extreme values (a modulus near the float64 limit, a
# step of 1e300 s in a run as long, ...): what they overflow is reported as the scene's fault, not with a traceback.
OUT_OF_RANGE = (OverflowError, ZeroDivisionError, FloatingPointError)


def _out_of_range(path, error) -> SceneError:
    return SceneError(str(path), f"the scene's numbers are out of range for the derived quantities ({error})",
                      "check the magnitudes and units of time.dt and time.end, the moduli, densities, radii and "
                      "coordinates")


def _validate_as_run(scene, base_dir) -> tuple:
    """What `run` reads before its first step, read the same way: the insertion, the mesh-wall
    files, the solids' meshes, and the checks that relate them (coordinates, domain.box, periodic
    lengths, particles starting behind or deep in a wall or inside a solid).
    Returns (the number of particles placed, the solids by name or None, the mesh walls' warnings)."""
    from pdemfem.contact.tables import build_contact_tables
    from pdemfem.particles.insert import insert_particles
    from pdemfem.particles.stream import validate_streams
    from pdemfem.scene import derived
    from pdemfem.scene.inputs import start_solids, start_surfaces, validate_geometry, validate_scene_coordinates
    from pdemfem.scene.loader import resolve_path
    from pdemfem.walls.factory import build_contributor_walls

    validate_scene_coordinates(scene)
    # The contact table as the run builds it (a derived linear stiffness needs an impact speed).
    build_contact_tables(scene, characteristic_speed=derived.expected_impact_speed(scene))
    inserted = insert_particles(scene)
    validate_streams(scene)
    walls = build_contributor_walls(scene.walls, list(scene.materials), lambda file: resolve_path(base_dir, file))
    solids = build_scene_solids(scene, base_dir) if scene.solids else None
    surfaces = []
    if solids and len(inserted.radii):
        for config in scene.solids:
            if config.contact:
                solid = solids[config.name]
                contact = solid.contact_surface()
                _, positions, _ = solid.surface_state()
                surfaces.append((config.name, positions, contact.triangles))
    validate_geometry(scene, inserted, [(wall.name, wall.vertices) for wall in walls if hasattr(wall, "vertices")],
                      surfaces=start_surfaces(scene, walls, surfaces),
                      solids=start_solids(scene, solids) if solids else ())
    return len(inserted.radii), solids, derived.mesh_wall_warnings(scene, walls)


def build_scene_solids(scene, base_dir) -> dict:
    """The scene's solids for `check` (each rank whole, no static solve); a misnamed mesh group is a
    SceneError naming its key (solids[i].fixed[k], ...)."""
    from pdemfem.coupling.check import build_solids
    from pdemfem.scene.inputs import solid_errors_named

    with solid_errors_named(scene):
        return build_solids(scene, base_dir)


def _stream_text(insert) -> str:
    """'stream of 400/s' or 'stream of 0.5 kg/s' (docs/streams.md)."""
    return f"stream of {insert.rate:g}/s" if insert.rate is not None else f"stream of {insert.mass_rate:g} kg/s"


def _clump_sphere_count(group) -> int:
    from pdemfem.clumps.template import clump_spheres

    return len(clump_spheres(group.clump)[1])


# Measured: a 240,477-DOF P1 block (gmsh) took 737 MB per rank on 2 ranks for a short run, 1.07 GB above the two
# ranks' ~200 MB baseline: PETSc's matrices and vectors and the static start's multigrid, ~4.5 KB per DOF.
SOLID_BYTES_PER_DOF = 4500


def _solid_memory_text(solids) -> str:
    """' + ~X for the solids (N DOF, all ranks)' for built solids; '' without."""
    if not solids:
        return ""
    dofs = sum(3 * solid.n_global_nodes for solid in solids.values())
    return (f" + ~{_format_bytes(dofs * SOLID_BYTES_PER_DOF)} for the solids ({dofs} DOF at ~{SOLID_BYTES_PER_DOF} "
            f"B/DOF, all ranks)")


def _report(path, scene, base_dir, placed, solids=None, mesh_warnings=()) -> tuple:
    from pdemfem.scene import derived
    from pdemfem.scene.loader import scene_hash

    counts = derived.group_counts(scene)
    total = derived.particle_count(scene)
    lines = [f"scene: {path} (physics hash {scene_hash(scene)[:12]})"]
    groups = ", ".join(
        f"{group.name}: {_stream_text(group.insert) if group.insert.kind == 'stream' else count} {group.material}"
        + (f" clumps of {_clump_sphere_count(group)} spheres" if group.clump is not None else "")
        + f", r = {_radius_text(derived.group_radius_range(group))}"
        for group, count in zip(scene.particles, counts)
    )
    spheres = sum(count * _clump_sphere_count(group) for group, count in zip(scene.particles, counts)
                  if group.clump is not None) + sum(count for group, count in zip(scene.particles, counts)
                                                    if group.clump is None)
    lines.append(f"particles: {total}" + (f" ({groups})" if groups else "")
                 + ("" if placed is None or placed == spheres else f"; inserted {placed}")
                 + (f"; {spheres} spheres" if spheres != total else ""))
    lines.append(f"walls: {len(scene.walls)}" + (f" ({', '.join(w.name for w in scene.walls)})" if scene.walls else ""))
    models = sorted({interaction.model for interaction in scene.interactions.values()})
    lines.append(f"materials: {', '.join(scene.materials)}; contact models: {', '.join(models)}")

    rayleigh = derived.rayleigh_time(scene)
    from pdemfem.coupling.check import HELD_FORCE_MARGIN, held_force_step_limit

    # The solids are built once, here: for the step without particles, the held-force limit and the report.
    if solids is None and scene.solids:
        solids = build_scene_solids(scene, base_dir)
    solid_step = (min(solid.critical_time_step() for solid in solids.values())
                  if solids and not scene.particles else None)
    dt = derived.time_step(scene, solid_critical_step=solid_step)
    if scene.time.dt == "auto":
        why = derived.time_step_choice(scene, solid_step)[1]
        held_limit, held_by = held_force_step_limit(scene, solids) if solids else (math.inf, None)
        if dt > HELD_FORCE_MARGIN * held_limit:  # as run does (Simulation): a yielding surface's node sets the step
            dt = HELD_FORCE_MARGIN * held_limit
            why = (f"{HELD_FORCE_MARGIN:g} x the {held_limit:.3g} s the contact force held on solid {held_by}'s "
                   f"lightest surface node allows (S_n dt^2 / (4 m) <= 1); the particles' own limit was {why}")
        lines.append(f"time step: dt = {dt:.3g} s (auto: {why})")
    else:
        rayleigh_text = f" = {dt / rayleigh:.3g} x Rayleigh time {rayleigh:.3g} s" if rayleigh else ""
        lines.append(f"time step: dt = {dt:.3g} s (given{rayleigh_text})")
    steps = derived.steps_to_end(scene.time.end, dt)  # the count `run` takes (Simulation.run)
    lines.append(f"steps: {steps} to time.end = {scene.time.end:g} s")
    streams = any(group.insert.kind == "stream" for group in scene.particles)
    if total or streams:
        speed, how = derived.impact_speed_estimate(scene)
        lines.append(f"impact speed: {speed:.3g} m/s ({how})")
        if 0.0 < speed < float("inf"):  # an overflowing initial velocity is a warning (derived.warnings)
            durations = derived.contact_duration(scene, speed)
            parts = []
            for label, value in (("particle-particle", durations.particle_particle),
                                 ("particle-wall", durations.particle_wall)):
                if value is not None:
                    parts.append(f"{label} {value:.3g} s")
            shortest = durations.shortest
            if shortest is None:
                lines.append("contact duration: no contacts possible (one particle, no walls)")
            else:
                pair, steps_per_contact, need = derived.tightest_contact_resolution(scene, speed, dt)
                lines.append(f"contact duration at {speed:.3g} m/s: {', '.join(parts)}; "
                             f"dt = {dt / shortest:.3g} of the shortest ({shortest / dt:.1f} steps per contact); "
                             f"tightest for its restitution: {pair}, {steps_per_contact:.1f} steps, wants >= "
                             f"{need:.0f}")
        per_particle = derived.bytes_per_particle(derived.contact_history_columns(scene))
        memory = derived.sphere_count(scene) * per_particle  # derived.memory_estimate_bytes
        lines.append(f"memory: ~{_format_bytes(memory)} for the particles ({per_particle} B/particle, "
                     f"all ranks) + ~200 MB per rank for Python, numba and PETSc" + _solid_memory_text(solids))
        lines.append(f"work: {total * steps:.3g} particle-steps" + (" for the particles placed at the start (the "
                                                                   "streams' add to it)" if streams else ""))
        thermal = derived.thermal_step_limit(scene)
        if scene.heat_enabled:
            lines.append("heat: on (contact conduction" + (", solids conduct" if scene.solids else "") + ")" + (
                f"; thermal step limit ~{thermal[0]:.3g} s ({thermal[1]}), dt is {dt / thermal[0]:.2g} of it"
                if thermal is not None else ""))
    found = derived.warnings(scene, solid_critical_step=solid_step, dt=dt) + list(mesh_warnings)
    if scene.solids:
        from pdemfem.coupling.check import coupling_report

        lines.extend(coupling_report(scene, base_dir, dt, warnings=found, solids=solids))
    return lines, found


def _radius_text(bounds) -> str:
    low, high = bounds
    return f"{low:g} m" if low == high else f"{low:g}-{high:g} m"


def _command_check(arguments, comm) -> int:
    # Every rank parses and builds the same scene (cheap), so errors are raised on
    # all ranks together; only rank 0 prints.
    lines, found = check_report(arguments.scene)
    for line in lines:
        _say(comm, line)
    if found:
        _say(comm, f"warnings ({len(found)}):")
        for warning in found:
            _say(comm, f"  - {warning}")
    else:
        _say(comm, "warnings: none")
    _say(comm, "scene OK")
    return 1 if (found and arguments.strict) else 0


# --------------------------------------------------------------------------- info


def info_lines(comm) -> tuple:
    """([(name, value)], missing) describing the installation."""
    import platform

    rows = [("pdemfem", pdemfem.__version__), ("python", f"{platform.python_version()} ({sys.executable})")]
    missing = []

    def probe(name, function):
        try:
            rows.append((name, function()))
        except Exception as error:  # report, do not crash: info is for diagnosing installs
            rows.append((name, f"MISSING ({type(error).__name__}: {error})"))
            missing.append(name)

    def numpy_version():
        import numpy

        return numpy.__version__

    def numba_version():
        import numba

        return numba.__version__

    def petsc_version():
        import petsc4py
        from pdemfem.fem.petsc import PETSc

        major, minor, patch = PETSc.Sys.getVersion()
        return f"{major}.{minor}.{patch} (petsc4py {petsc4py.__version__}, PETSC_DIR={os.environ.get('PETSC_DIR', '')})"

    def mpi_version():
        import mpi4py
        from mpi4py import MPI

        library = MPI.Get_library_version().strip().splitlines()[0].split(", ident")[0].rstrip(",")
        major, minor = MPI.Get_version()
        return f"{library} (MPI {major}.{minor}, mpi4py {mpi4py.__version__})"

    def h5py_version():
        import h5py

        parallel = bool(h5py.get_config().mpi)
        return f"{h5py.__version__} (HDF5 {h5py.version.hdf5_version}); MPI-parallel: {'yes' if parallel else 'NO'}"

    probe("numpy", numpy_version)
    probe("numba", numba_version)
    probe("petsc", petsc_version)
    probe("mpi", mpi_version)
    rows.append(("ranks", str(comm.size)))
    probe("h5py", h5py_version)
    return rows, missing


def _command_info(arguments, comm) -> int:
    rows, missing = info_lines(comm)
    width = max(len(name) for name, _ in rows)
    for name, value in rows:
        _say(comm, f"{name:<{width}}  {value}")
    if missing:
        raise PdemfemError("pdemfem info", f"missing: {', '.join(missing)}", "run `make install` (see README)")
    return 0


# --------------------------------------------------------------------------- plot


def _command_plot(arguments, comm) -> int:
    from pdemfem.plot import plot_history

    written = _on_root(comm, lambda: [str(path) for path in plot_history(arguments.outdir)])
    if written:
        for path in written:
            _say(comm, f"wrote {path}", arguments.quiet)
    return 0


# --------------------------------------------------------------------------- render


def _command_render(arguments, comm) -> int:
    from pdemfem import render

    if arguments.gallery:
        if arguments.outdir is not None:
            raise PdemfemError("pdemfem render", "--gallery runs the examples itself; it takes no OUTDIR",
                               "pdemfem render --gallery, or pdemfem render OUTDIR")
        render.build_gallery(comm, arguments.runs, say=lambda text: _say(comm, text, arguments.quiet),
                             renderer=arguments.renderer, pvpython=arguments.pvpython)
        return 0
    if arguments.outdir is None:
        raise PdemfemError("pdemfem render", "no output directory given",
                           "pdemfem render OUTDIR [--scene scene.yaml], or pdemfem render --gallery")
    written = _on_root(comm, lambda: str(render.render_output(arguments.outdir, scene=arguments.scene,
                                                               target=arguments.output, renderer=arguments.renderer,
                                                               pvpython=arguments.pvpython)))
    _say(comm, f"wrote {written}", arguments.quiet)
    return 0


if __name__ == "__main__":
    sys.exit(main())

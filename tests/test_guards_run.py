"""Guards in `pdemfem run`: the run monitor stops diverging runs with exit 3, a final output step,
a checkpoint when checkpoints are on, and a diagnosis; `run` repeats `check`'s warnings.

Each scene is a small version of a case that used to run to the end with exit 0 and garbage in
the history (docs/stability_guards.md lists the before/after figures).
"""
from __future__ import annotations

import os

import csv
import math
import subprocess
import sys
from pathlib import Path

import numpy as np
import pytest

from pdemfem import Simulation, cli
from pdemfem.errors import SolverError
from pdemfem.io.checkpoint import checkpoint_path
from pdemfem.runtime import mpiexec_command, process_environment

SOFT_GLASS = "glass: {density: 2500, youngs_modulus: 5.0e6, poisson_ratio: 0.3}"

# 30 beads above a floor at dt = 1e-3 s, 8 x the Rayleigh time: the contacts explode.
COARSE_BEADS = f"""\
time: {{end: 0.02, dt: 1.0e-3}}
gravity: [0, 0, -9.81]
materials:
  {SOFT_GLASS}
interactions:
  default: {{model: hertz_mindlin, restitution: 0.5, friction: 0.5}}
particles:
  - name: beads
    material: glass
    radius: 0.001
    insert:
      kind: random
      region: {{box: [[0, 0, 0], [0.01, 0.01, 0.01]]}}
      count: 30
      seed: 1
walls:
  - {{name: floor, kind: plane, point: [0, 0, 0], normal: [0, 0, 1], material: glass}}
output: {{dir: out, every: 0.002}}
"""

# One sphere whose centre starts 0.5 mm behind the floor (radius 1 mm).
BEHIND_PLANE = f"""\
time: {{end: 0.002, dt: auto}}
gravity: [0, 0, -9.81]
materials:
  {SOFT_GLASS}
particles:
  - name: ball
    material: glass
    radius: 0.001
    insert: {{kind: list, positions: [[0, 0, -0.0005]]}}
walls:
  - {{name: floor, kind: plane, point: [0, 0, 0], normal: [0, 0, 1], material: glass}}
output: {{dir: out, every: 0.0005}}
"""

# One particle at 1e200 m/s: its kinetic energy overflows.
OVERFLOW = f"""\
time: {{end: 0.001, dt: DT}}
gravity: [0, 0, 0]
materials:
  {SOFT_GLASS}
particles:
  - name: ball
    material: glass
    radius: 0.001
    insert: {{kind: list, positions: [[0, 0, 0.01]], velocities: [[0, 0, 1.0e200]]}}
walls:
  - {{name: floor, kind: plane, point: [0, 0, 0], normal: [0, 0, 1], material: glass}}
output: {{dir: out, every: 0.0001}}
"""

# Two spheres closing at 5 m/s with e = 1e-4: the calibrated dashpot (gamma = 91) needs
# omega dt < 2 / gamma, far below the old default dt (0.2 Rayleigh times).
STICKY_PAIR = f"""\
time: {{end: 0.0005, dt: DT}}
gravity: [0, 0, 0]
materials:
  {SOFT_GLASS}
interactions:
  default: {{model: MODEL, restitution: 1.0e-4, friction: 0.5}}
particles:
  - name: pair
    material: glass
    radius: 0.001
    insert:
      kind: list
      positions: [[0, 0, 0], [0.0021, 0, 0]]
      velocities: [[2.5, 0, 0], [-2.5, 0, 0]]
output: {{dir: out, every: 0.0001}}
CHECKPOINT"""

OLD_DEFAULT_DT = "2.45e-5"  # 0.2 x the Rayleigh time of the 1 mm soft glass sphere (the old dt: auto)


@pytest.fixture
def workdir(tmp_path, monkeypatch):
    monkeypatch.chdir(tmp_path)
    return tmp_path


def run_cli(capsys, folder: Path, text: str):
    path = folder / "scene.yaml"
    path.write_text(text)
    code = cli.main(["run", str(path), "--quiet", "-o", str(folder / "out")])
    out, err = capsys.readouterr()
    return code, out, err


def history(folder: Path) -> list:
    with open(folder / "out" / "history.csv") as handle:
        return list(csv.DictReader(handle))


def test_coarse_step_stops_with_exit_3_and_names_the_limits(capsys, workdir):
    code, _, err = run_cli(capsys, workdir, COARSE_BEADS)
    assert code == 3, err
    assert err.count("error: ") == 1 and "Traceback" not in err
    assert "the simulation diverged: " in err
    assert "above the elastic wave limit" in err and "steps per particle-particle contact" in err
    # run repeated check's warnings first
    assert "warning: time.dt = 0.001 s is 8.17 x the Rayleigh time" in err
    rows = history(workdir)
    # The stop wrote its output step: the last row is the step the monitor stopped at, before the end.
    assert 0 < int(rows[-1]["step"]) < 20
    # Before the guard the run reached t = 0.02 s with ~1e8 J in the 30 beads (4e-6 J available).
    assert float(rows[-1]["kinetic_energy"]) < 1.0


def test_sphere_started_behind_a_plane_is_a_scene_error(capsys, workdir):
    """The validation refuses it before anything is written (it used to run and be stopped at step 0 by the
    run monitor, and before that guard the sphere was shot out)."""
    code, _, err = run_cli(capsys, workdir, BEHIND_PLANE)
    assert code == 2, err
    assert err.count("error:") == 1 and "Traceback" not in err
    assert "behind plane wall 'floor'" in err, err
    assert not (workdir / "out").exists()


# A 1 mm soft glass bead set at its static Hertz overlap on the floor: delta = (3 m g / (4 E* sqrt(R)))^(2/3)
# = 9.25e-7 m (E* = E / (2 (1 - nu^2)), m = 1.047e-5 kg): 9.25e-4 radii, a settled packing's overlap.
RESTING_BEAD = f"""\
time: {{end: 0.01, dt: auto}}
gravity: [0, 0, -9.81]
materials:
  {SOFT_GLASS}
interactions:
  default: {{model: hertz_mindlin, restitution: 0.5, friction: 0.5}}
particles:
  - name: bead
    material: glass
    radius: 0.001
    insert: {{kind: list, positions: [[0, 0, 0.000999075]]}}
walls:
  - {{name: floor, kind: plane, point: [0, 0, 0], normal: [0, 0, 1], material: glass}}
output: {{dir: out, every: 0.001}}
"""


def test_a_bead_started_at_its_resting_overlap_runs_and_stays_at_rest(capsys, workdir):
    """The monitor counted the starting overlap's elastic energy (3.8e-11 J here) as created and stopped the
    run at step 0 as diverged, and `check` warned that the bead starts inside the floor.  Starting overlaps
    up to 0.05 radii are accepted (deeper ones are refused before the run), so their energy is available."""
    (workdir / "scene.yaml").write_text(RESTING_BEAD)
    assert cli.main(["check", str(workdir / "scene.yaml")]) == 0
    out, _ = capsys.readouterr()
    assert "warnings: none" in out, out
    code, _, err = run_cli(capsys, workdir, RESTING_BEAD)
    assert code == 0, err
    rows = history(workdir)
    assert float(rows[-1]["time"]) >= 0.01
    weight_work = 2500 * 4.0 / 3.0 * math.pi * 1e-9 * 9.81 * 9.25e-7  # m g delta
    # At rest: the placed overlap is Hertz's to ~1e-4, so the bead rings with ~(1e-4)^2 of m g delta.
    assert max(float(row["kinetic_energy"]) for row in rows) < 1e-6 * weight_work


# Two 1 mm beads listed with their centres OVERLAP radii closer than touching, no gravity, e = 1.
PRESSED_PAIR = f"""\
time: {{end: 0.002, dt: auto}}
gravity: [0, 0, 0]
materials:
  {SOFT_GLASS}
interactions:
  default: {{model: hertz_mindlin, restitution: 1.0, friction: 0.0}}
particles:
  - name: pair
    material: glass
    radius: 0.001
    insert: {{kind: list, positions: [[0, 0, 0], [GAP, 0, 0]]}}
output: {{dir: out, every: 0.0002}}
"""


def test_listed_particles_may_start_at_contact_overlaps_and_their_energy_is_kept(capsys, workdir):
    """A settled packing listed by its positions has contact overlaps of 1e-3..1e-2 radii: accepted up to 0.05
    of the smaller radius (as against a wall), and the run starts with their elastic energy: released by the
    undamped pair, it comes back as kinetic energy (velocity Verlet's error at ~30 steps per contact: ~1e-3)."""
    code, _, err = run_cli(capsys, workdir, PRESSED_PAIR.replace("GAP", repr(0.002 - 0.01 * 0.001)))
    assert code == 0, err
    rows = history(workdir)
    elastic = float(rows[0]["elastic_energy"])
    assert elastic > 0.0 and float(rows[-1]["contacts"]) == 0
    assert float(rows[-1]["kinetic_energy"]) == pytest.approx(elastic, rel=1e-2)
    (workdir / "out").rename(workdir / "first")
    code, _, err = run_cli(capsys, workdir, PRESSED_PAIR.replace("GAP", repr(0.002 - 0.06 * 0.001)))
    assert code == 2 and "particles 0 and 1 overlap at insertion" in err and "0.05 of the smaller radius" in err
    assert not (workdir / "out").exists()


def test_overflowing_velocity_stops_with_explicit_dt_and_is_refused_with_dt_auto(capsys, workdir):
    code, _, err = run_cli(capsys, workdir, OVERFLOW.replace("DT", "2.0e-5"))
    assert code == 3, err
    # check warns instead of dividing by the zero contact duration (it raised ZeroDivisionError)
    code = cli.main(["check", str(workdir / "scene.yaml")])
    out, check_err = capsys.readouterr()
    assert code == 0 and "the impact speed is inf m/s" in out, (out, check_err)
    assert "non-finite energies (kinetic_energy)" in err
    assert "infinite or NaN velocity" in err
    # dt auto cannot resolve contacts at an infinite impact speed: a scene error (exit 2), no output.
    (workdir / "out").rename(workdir / "first")
    code, _, err = run_cli(capsys, workdir, OVERFLOW.replace("DT", "auto"))
    assert code == 2, err
    assert "time.dt" in err and "initial velocities" in err
    assert not (workdir / "out").exists()


@pytest.mark.parametrize("model", ["hertz_mindlin", "linear_spring_dashpot"])
def test_tiny_restitution_blows_up_at_the_old_default_and_is_stable_with_dt_auto(capsys, workdir, model):
    scene = STICKY_PAIR.replace("MODEL", model)
    with_checkpoints = scene.replace("DT", OLD_DEFAULT_DT).replace("CHECKPOINT", "checkpoint: {every: 0.0001}\n")
    code, _, err = run_cli(capsys, workdir, with_checkpoints)
    assert code == 3, err
    assert "the restitution is too small for the step" in err
    rows = history(workdir)
    stopped = int(rows[-1]["step"])
    # Checkpoints were on (every 1e-4 s = 4 steps): the stop wrote one of its own step.
    # It is kept apart from the good ones: latest.h5 stays on the last checkpoint before the stop (none when the
    # stop came before the first).
    folder = workdir / "out" / "checkpoints"
    diverged = checkpoint_path(folder, stopped)
    assert diverged.with_name(f"{diverged.stem}_diverged.h5").exists(), sorted(folder.iterdir())
    before = (stopped - 1) // 4 * 4  # the last scheduled checkpoint before the stop (0: none)
    if before:
        assert os.path.samefile(folder / "latest.h5", checkpoint_path(folder, before))
    else:
        assert not (folder / "latest.h5").exists() and "there is no checkpoint before it" in err
    (workdir / "out").rename(workdir / "coarse")
    code, _, err = run_cli(capsys, workdir, scene.replace("DT", "auto").replace("CHECKPOINT", ""))
    assert code == 0, err
    rows = history(workdir)
    initial = float(rows[0]["kinetic_energy"])
    # A nearly plastic contact: at most e^2 = 1e-8 of the kinetic energy comes back; the step error
    # adds ~1 % of e (docs/stability_guards.md), so anything above 1e-6 of it would be the dashpot
    # instability.  Before dt auto resolved the dashpot, ~1000 x the initial energy came out.
    assert float(rows[-1]["kinetic_energy"]) < 1e-6 * initial


def _tunnelling_scene(folder: Path, surface: str, dt: str, youngs_modulus: str, speed: float,
                      height: float = 0.006) -> str:
    sheet = ""
    if surface == "sheet":
        import meshio

        xs = np.linspace(-0.02, 0.02, 5)
        points = np.array([[x, y, 0.0] for x in xs for y in xs])
        triangles = []
        for i in range(4):
            for j in range(4):
                a, b = 5 * i + j, 5 * (i + 1) + j
                triangles += [[a, b, b + 1], [a, b + 1, a + 1]]
        meshio.write(str(folder / "sheet.msh"), meshio.Mesh(points, [("triangle", np.array(triangles))]),
                     file_format="gmsh22", binary=True)
        sheet = "walls:\n  - {name: sheet, kind: mesh, file: sheet.msh, material: steel}\n"
    else:
        sheet = ("solids:\n  - name: plate\n"
                 "    mesh: {box: [[-0.02, -0.02, 0], [0.02, 0.02, 0.002]], cells: [2, 2, 1]}\n"
                 "    material: steel\n    fixed: [xmin, xmax]\n    contact: [zmax, zmin]\n")
    return f"""\
time: {{end: 3.0e-4, dt: {dt}}}
gravity: [0, 0, 0]
materials:
  ball: {{density: 2500, youngs_modulus: {youngs_modulus}, poisson_ratio: 0.3}}
  steel: {{density: 7800, youngs_modulus: 2.0e11, poisson_ratio: 0.3}}
particles:
  - name: ball
    material: ball
    radius: 0.001
    insert: {{kind: list, positions: [[0, 0, {height}]], velocities: [[0, 0, -{speed}]]}}
{sheet}output: {{dir: out, every: 5.0e-5}}
"""


@pytest.mark.parametrize("surface", ["sheet", "plate"])
def test_tunnelling_is_never_silent(capsys, workdir, surface):
    # 1 mm soft sphere at 100 m/s, dt 0.2 Rayleigh times: 2.45 radii per step.
    code, _, err = run_cli(capsys, workdir, _tunnelling_scene(workdir, surface, OLD_DEFAULT_DT, "5.0e6", 100))
    assert code == 3, err
    assert "tunnelling: a particle moved at 100 m/s, 2.45 radii per step" in err
    assert "can tunnel through the thin surface" in err  # run repeated check's warning
    (workdir / "out").rename(workdir / "coarse")
    # dt auto resolves the contact, but so soft a sphere at 100 m/s overlaps 3.2 radii: it passes
    # through whatever the step, so that is refused too.
    code, _, err = run_cli(capsys, workdir, _tunnelling_scene(workdir, surface, "auto", "5.0e6", 100))
    assert code == 3, err
    assert "overlaps 3.2 radii" in err


@pytest.mark.parametrize("surface", ["sheet", "plate"])
def test_stiff_sphere_bounces_off_with_dt_auto(workdir, surface):
    """The positive case of the tunnelling guard: a stiff sphere at 10 m/s rebounds upwards, on the
    surface's side (plate top at z = 2 mm, sheet at 0)."""
    # Starts 0.5 mm above touching: contact after 5e-5 s, rebound long before the end (3e-4 s).
    height = (0.002 if surface == "plate" else 0.0) + 0.0015
    text = _tunnelling_scene(workdir, surface, "auto", "2.0e11", 10, height=height)
    (workdir / "scene.yaml").write_text(text)
    simulation = Simulation.from_file(workdir / "scene.yaml", output_dir=workdir / "api")
    simulation.run(progress=False)
    assert simulation.particles.velocities[0, 2] > 0.0
    assert simulation.particles.positions[0, 2] > (0.002 if surface == "plate" else 0.0)


def test_monitor_is_quiet_on_a_stable_run_and_the_stop_is_a_solver_error(workdir):
    """Stable runs are untouched (the demo-like beads with dt auto); a diverging one raises
    SolverError (exit code 3) from Simulation.run, with stopped_by = "divergence"."""
    stable = Simulation.from_dict(_yaml(COARSE_BEADS.replace("dt: 1.0e-3", "dt: auto")), base_dir=workdir,
                                  output_dir=workdir / "stable")
    stable.run(progress=False)
    assert stable.step_count > 100 and stable.stopped_by is None
    coarse = Simulation.from_dict(_yaml(COARSE_BEADS), base_dir=workdir, output_dir=workdir / "coarse")
    with pytest.raises(SolverError) as raised:
        coarse.run(progress=False)
    assert raised.value.exit_code == 3 and coarse.stopped_by == "divergence"


def test_dissipated_energy_does_not_rise_in_free_flight(workdir):
    """No contact, no force: the dissipated energy stays exactly where it was (it was 0.03 J
    per step in the old tunnelling runs only while a contact force acted)."""
    text = _tunnelling_scene(workdir, "sheet", OLD_DEFAULT_DT, "5.0e6", 10)
    (workdir / "scene.yaml").write_text(text)
    simulation = Simulation.from_file(workdir / "scene.yaml", output_dir=workdir / "api")
    for _ in range(10):
        before = simulation.particle_system.dissipated_energy
        simulation.step()
        if simulation.contact_count() == 0 and not np.any(simulation.particles.forces):
            assert simulation.particle_system.dissipated_energy == before


def _yaml(text: str) -> dict:
    import yaml

    return yaml.safe_load(text)


@pytest.mark.mpi
def test_divergence_under_mpi_stops_every_rank_with_exit_3_and_one_message(workdir):
    path = workdir / "scene.yaml"
    path.write_text(COARSE_BEADS)
    command = mpiexec_command(2, [sys.executable, "-m", "pdemfem.cli", "run", str(path), "--quiet"])
    environment = dict(process_environment(), PYTHONFAULTHANDLER="1")  # a crash shows where, not just 139
    completed = subprocess.run(command, env=environment, cwd=workdir, capture_output=True, text=True, timeout=180)
    assert completed.returncode == 3, completed.stderr
    assert completed.stderr.count("error: ") == 1, completed.stderr
    assert "the simulation diverged" in completed.stderr and "Traceback" not in completed.stderr
    # The warnings are printed once (rank 0), not once per rank.
    assert completed.stderr.count("warning: time.dt = 0.001 s") == 1, completed.stderr


# A user's script whose rank 1 fails in a local query (a misspelt wall) while rank 0 steps on.
ONE_RANK_FAILS = """\
import sys
from mpi4py import MPI
from pdemfem import Simulation
simulation = Simulation.from_file(sys.argv[1])
simulation.step(5)
simulation.wall_force("flor" if MPI.COMM_WORLD.rank == 1 else "floor")
simulation.step(5)
"""


@pytest.mark.mpi
def test_an_error_on_one_rank_of_a_script_aborts_the_job_instead_of_hanging(workdir):
    """Rank 1's KeyError ended its script, rank 0 waited in the next step's collective, and rank 1 in MPI's
    finalisation: the job hung until killed.  Now the uncaught exception aborts the job (exit 1, the
    traceback and which rank)."""
    (workdir / "scene.yaml").write_text(RESTING_BEAD)
    (workdir / "script.py").write_text(ONE_RANK_FAILS)
    command = mpiexec_command(2, [sys.executable, str(workdir / "script.py"), str(workdir / "scene.yaml")])
    completed = subprocess.run(command, env=process_environment(), cwd=workdir, capture_output=True, text=True,
                               timeout=120)
    assert completed.returncode != 0, completed.stderr
    assert "no wall or contact solid named 'flor'" in completed.stderr, completed.stderr
    assert "(rank 1 of 2) the exception above ended this rank" in completed.stderr, completed.stderr


# Two soft steel spheres closing head-on at SPEED m/s (dt auto).  The Hertz peak overlap of the impact
# scales as E^(-2/5): 3 radii at E = 1 MPa, 0.48 at 100 MPa, 0.19 at 1 GPa.
CLOSING_PAIR = """\
time: {end: 0.002, dt: auto}
gravity: [0, 0, 0]
materials:
  steel: {density: 7800, youngs_modulus: MODULUS, poisson_ratio: 0.28}
interactions:
  default: {model: hertz_mindlin, restitution: 0.95, friction: 0.0}
particles:
  - name: pair
    material: steel
    radius: 0.001
    insert: {kind: list, positions: [[0, 0, 0], [0, 0, 0.0021]], velocities: [[0, 0, 10], [0, 0, -10]]}
output: {dir: out, every: 0.0005}
"""


def test_spheres_that_would_pass_through_each_other_stop_the_run(capsys, workdir):
    """So soft a pair at 20 m/s overlaps by more than a radius: the spheres' centres cross and they fly on
    through each other (before the guard: exit 0 with a negative restitution, -0.97).  check says so,
    and the run stops with exit 3."""
    scene = CLOSING_PAIR.replace("MODULUS", "1.0e6")
    (workdir / "scene.yaml").write_text(scene)
    assert cli.main(["check", str(workdir / "scene.yaml")]) == 0
    out, _ = capsys.readouterr()
    assert "peak overlap is 3 of the smaller radius, so the spheres pass through each other" in out
    code, _, err = run_cli(capsys, workdir, scene)
    assert code == 3, err
    assert "overlapped by" in err and "pass through each other" in err and "Traceback" not in err
    rows = history(workdir)
    # It stopped inside the contact (0.45 ms from first touch at ~5e-6 s), not at time.end (2 ms).
    assert float(rows[-1]["time"]) < 0.001


@pytest.mark.parametrize("modulus, warned", [("1.0e8", True), ("1.0e9", False)])
def test_deep_overlaps_are_warned_about_once(capsys, caplog, workdir, modulus, warned):
    """At E = 100 MPa the impact overlaps ~0.48 radii: the run ends normally (the spheres separate) but
    warns once, at run time (the "pdemfem" logger), beyond PEAK_OVERLAP_WARNING = 0.25; at 1 GPa (0.19
    radii) it stays quiet."""
    code, _, err = run_cli(capsys, workdir, CLOSING_PAIR.replace("MODULUS", modulus))
    assert code == 0, err
    logged = [record.getMessage() for record in caplog.records if "overlapped by" in record.getMessage()]
    assert len(logged) == (1 if warned else 0), logged
    if warned:
        # The kernels' record is the impact's deepest overlap: Hertz's undamped peak 0.48 radii, a few per
        # cent less with the e = 0.95 dashpot (printed to 3 digits).
        measured = float(logged[0].split("overlapped by ")[1].split()[0])
        assert 0.45 < measured < 0.48, logged[0]
    assert ("the peak overlap is" in err) == warned  # check's estimate, repeated by run
    rows = history(workdir)
    assert float(rows[-1]["kinetic_energy"]) > 0.8 * float(rows[0]["kinetic_energy"])  # e = 0.95: they bounced


SPHERE_ON_STEEL_BLOCK = """
time: {end: 0.0004, dt: auto}
gravity: [0, 0, 0]
materials:
  soft: {density: 7800, youngs_modulus: 1.0e8, poisson_ratio: 0.28}
  steel: {density: 7800, youngs_modulus: 2.0e11, poisson_ratio: 0.28}
interactions:
  default: {model: hertz_mindlin, restitution: 0.95, friction: 0.0}
particles:
  - name: ball
    material: soft
    radius: 0.001
    insert: {kind: list, positions: [[0.005, 0.005, 0.01105]], velocities: [[0, 0, -SPEED]]}
solids:
  - name: block
    mesh: {box: [[0, 0, 0], [0.01, 0.01, 0.01]], cells: [1, 1, 1]}
    material: steel
    fixed: [zmin]
    contact: [zmax]
output: {dir: out, every: 0.0001}
"""


@pytest.mark.parametrize("speed, warned", [("20.0", True), ("5.0", False)])
def test_deep_overlaps_with_a_solid_surface_are_warned_about_once(capsys, caplog, workdir, speed, warned):
    """The triangle-surface contacts keep their deepest overlap for the monitor too: a soft sphere (E = 100 MPa,
    R = 1 mm) hitting a steel block at 20 m/s overlaps Hertz's (15 m v^2 / (16 E* sqrt(R)))^(2/5) = 0.42 radii
    (the block is 2000x stiffer: E* ~ the sphere's), past PEAK_OVERLAP_WARNING = 0.25; at 5 m/s 0.14 radii."""
    code, _, err = run_cli(capsys, workdir, SPHERE_ON_STEEL_BLOCK.replace("SPEED", speed))
    assert code == 0, err
    logged = [record.getMessage() for record in caplog.records if "overlapped by" in record.getMessage()]
    assert len(logged) == (1 if warned else 0), logged
    if warned:
        assert "triangle surface" in logged[0], logged[0]
        measured = float(logged[0].split("overlapped by ")[1].split()[0])
        # Hertz's undamped peak (the block's own compliance adds 0.05 %), a few per cent less with the dashpot.
        assert 0.38 < measured < 0.43, logged[0]


JELLY_BLOCK = """
time: {end: 0.01, dt: auto}
gravity: [0, 0, -9.81]
materials:
  grain: {density: 2500, youngs_modulus: 1.0e7, poisson_ratio: 0.25}
  jelly: {density: 1000, youngs_modulus: MODULUS, poisson_ratio: 0.3}
interactions:
  default: {model: hertz_mindlin, restitution: 0.5, friction: 0.3}
particles:
  - name: grain
    material: grain
    radius: 0.005
    insert: {kind: list, positions: [[0.05, 0.05, 0.2]]}
solids:
  - name: block
    mesh: {box: [[0, 0, 0], [0.1, 0.1, 0.1]], cells: [2, 2, 2]}
    material: jelly
    fixed: [zmin]
    contact: [zmax]
output: {dir: out, every: 0.001}
"""


@pytest.mark.parametrize("modulus, stops", [("20.0", True), ("2.0e5", False)])
def test_a_solid_turned_inside_out_stops_the_run(capsys, workdir, modulus, stops):
    """A 10 cm block with E = 20 Pa (kPa or MPa meant) sags under its own weight by ~rho g H^2 / (2 E) = 2.5 m
    in the static start, 50x its cells: cells turn inside out, where the linear model means nothing and the top
    no longer bounds the solid.  The monitor stops before the first step, naming the solid and the key to check.
    At E = 200 kPa (2.5 mm, 5 % of a cell) the run goes to the end."""
    code, _, err = run_cli(capsys, workdir, JELLY_BLOCK.replace("MODULUS", modulus))
    if stops:
        assert code == 3, err
        assert "solid 'block'" in err and "turned inside out" in err and "solids[0]" in err, err
        assert "youngs_modulus" in err and "Traceback" not in err, err
        assert float(history(workdir)[-1]["time"]) == 0.0
    else:
        assert code == 0, err

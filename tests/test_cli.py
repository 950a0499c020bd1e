"""The `pdemfem` command: check/run/info/plot, and its error handling serially and under MPI.

Most cases call `pdemfem.cli.main` in this process (the same code path as the
console script, without the ~1 s interpreter start); a few run the real command
under mpiexec to prove that errors are printed once, every rank exits with the
same code, and nothing hangs.
"""
from __future__ import annotations

import os
import subprocess
import sys
import textwrap
from pathlib import Path

import pytest

from pdemfem import cli
from pdemfem.runtime import mpiexec_command, process_environment

ROOT = Path(__file__).resolve().parent.parent
DEMO = ROOT / "examples" / "demo.yaml"

SCENE = """\
time: {end: 0.002, dt: auto, dt_factor: 0.1}
materials:
  glass: {density: 2500, youngs_modulus: 5.0e6, poisson_ratio: 0.3}
particles:
  - name: grains
    material: glass
    radius: 0.001
    insert:
      kind: lattice
      region: {box: [[0, 0, 0], [0.01, 0.01, 0.01]]}
      count: 20
walls:
  - {name: floor, kind: plane, point: [0, 0, 0], normal: [0, 0, 1], material: glass}
output: {dir: results, every: 0.001}
"""

# Bad scenes found only when the particles are built (pdemfem.particles.insert).
OVERFULL = SCENE.replace("count: 20", "count: 1000")  # a 1 cm box holds 4 x 4 x 4 at this spacing
OVERLAPPING = SCENE.replace(
    "      kind: lattice\n      region: {box: [[0, 0, 0], [0.01, 0.01, 0.01]]}\n      count: 20\n",
    "      kind: list\n      positions: [[0.005, 0.005, 0.005], [0.005, 0.005, 0.0065]]\n",
)
MISSPELT = SCENE.replace("count: 20", "cuont: 20")


@pytest.fixture
def workdir(tmp_path, monkeypatch):
    monkeypatch.chdir(tmp_path)
    return tmp_path


def write(folder: Path, name: str, text: str) -> Path:
    path = folder / name
    path.write_text(text)
    return path


def run_main(capsys, *argv):
    code = cli.main([str(a) for a in argv])
    out, err = capsys.readouterr()
    return code, out, err


# --------------------------------------------------------------------------- check


def test_check_prints_derived_quantities(capsys):
    code, out, err = run_main(capsys, "check", DEMO)
    assert code == 0, err
    for expected in ("particles: 2000", "walls: 5", "time step: dt = 7.71e-06 s", "Rayleigh time 0.00011 s",
                     "contact duration at 0.63 m/s", "steps per contact", "memory: ~1.92 MB",
                     "warnings: none", "scene OK"):
        assert expected in out, out
    assert err == ""


@pytest.mark.parametrize(
    "text, key, problem, fix",
    [
        (MISSPELT, "particles[0].insert.cuont", "unknown key 'cuont'", "did you mean 'count'?"),
        (OVERFULL, "particles[0].insert.count", "holds only 64 particles", "enlarge region.box, reduce count"),
        (OVERLAPPING, "particles[0].insert", "particles 0 and 1 overlap at insertion", "move the positions apart"),
    ],
    ids=["misspelt key", "insertion cannot place its count", "overlapping list insertion"],
)
def test_check_reports_bad_scenes(capsys, workdir, text, key, problem, fix):
    path = write(workdir, "scene.yaml", text)
    code, out, err = run_main(capsys, "check", path)
    assert code == 2
    assert err.startswith(f"error: {path}: line "), err
    first_line = err.splitlines()[0]
    assert key in first_line and problem in first_line, err
    assert f"fix: {fix}" in err
    assert "Traceback" not in err and "scene OK" not in out


def test_check_strict_fails_on_warnings(capsys, workdir):
    coarse = write(workdir, "coarse.yaml", SCENE.replace("dt: auto, dt_factor: 0.1", "dt: 2.0e-5"))
    code, out, _ = run_main(capsys, "check", coarse)
    # restitution 0.5: max(30, 90 gamma_lin^1.5) = 33 steps per contact (docs/restitution.md)
    assert code == 0 and "warnings (1)" in out and "33 steps per particle-particle contact" in out, out
    code, _, _ = run_main(capsys, "check", coarse, "--strict")
    assert code == 1


# --------------------------------------------------------------------------- run


@pytest.mark.parametrize("text", [MISSPELT, OVERFULL, OVERLAPPING], ids=["schema", "insertion", "overlap"])
@pytest.mark.parametrize("use_option", [False, True], ids=["scene output.dir", "-o DIR"])
def test_run_bad_scene_leaves_no_output_directory(capsys, workdir, text, use_option):
    path = write(workdir, "scene.yaml", text)
    options = ["-o", workdir / "given"] if use_option else []
    code, _, err = run_main(capsys, "run", path, "--quiet", *options)
    assert code == 2 and err.startswith(f"error: {path}: line "), err
    assert "particles[0].insert" in err.splitlines()[0]
    assert sorted(p.name for p in workdir.iterdir()) == ["scene.yaml"]


def test_run_writes_history_and_plot_draws_it(capsys, workdir):
    path = write(workdir, "scene.yaml", SCENE)
    code, out, err = run_main(capsys, "run", path, "--quiet")
    assert code == 0, err
    assert out == ""  # --quiet: no summary, no progress bar
    history = workdir / "results" / "history.csv"  # output.dir resolves relative to the scene file
    header = history.read_text().splitlines()[0].split(",")
    for column in ("time", "step", "particles", "kinetic_energy", "rotational_energy", "potential_energy",
                   "dissipated_energy", "force_floor_x", "force_floor_y", "force_floor_z"):
        assert column in header
    code, out, err = run_main(capsys, "plot", workdir / "results")
    assert code == 0, err
    for name in ("energies.png", "wall_forces.png", "particles.png"):
        png = workdir / "results" / "plots" / name
        assert png.read_bytes()[:8] == b"\x89PNG\r\n\x1a\n"
        assert f"wrote {png}" in out


# --------------------------------------------------------------------------- plot, info


def test_plot_reads_history_columns(capsys, workdir):
    folder = workdir / "run"
    folder.mkdir()
    (folder / "history.csv").write_text(
        "time,step,particles,kinetic_energy,potential_energy,force_left_wall_x,force_left_wall_y,force_left_wall_z\n"
        "0.0,0,10,0.0,1.0,0.0,0.0,0.0\n0.1,5,10,0.5,0.5,0.1,0.0,-2.0\n"
    )
    from pdemfem.plot import read_history

    data = read_history(folder / "history.csv")
    assert list(data["kinetic_energy"]) == [0.0, 0.5] and list(data["force_left_wall_z"]) == [0.0, -2.0]
    code, out, _ = run_main(capsys, "plot", folder, "--quiet")
    assert code == 0 and out == ""
    # The particle count is constant (10): no figure for it (tests/test_history_plot.py).
    assert sorted(p.name for p in (folder / "plots").iterdir()) == ["energies.png", "wall_forces.png"]


def test_plot_without_history_is_a_clear_error(capsys, workdir):
    (workdir / "empty").mkdir()
    code, _, err = run_main(capsys, "plot", workdir / "empty")
    assert code == 2
    assert err.startswith(f"error: {workdir / 'empty' / 'history.csv'}: history.csv not found")
    assert "fix: run a scene first" in err
    assert not (workdir / "empty" / "plots").exists()


def test_info_lists_the_stack(capsys):
    code, out, err = run_main(capsys, "info")
    assert code == 0, err
    import numpy

    assert f"numpy    {numpy.__version__}" in out
    for name in ("python", "numba", "petsc", "mpi", "ranks", "h5py"):
        assert any(line.startswith(f"{name} ") for line in out.splitlines()), out
    assert "ranks    1" in out
    assert "MPI-parallel: " in out


# --------------------------------------------------------------------------- real processes


def run_command(argv, ranks=1, cwd=None, timeout=120, extra_env=None):
    command = [sys.executable, *map(str, argv)]
    if ranks > 1:
        command = mpiexec_command(ranks, command)
    environment = process_environment()
    environment.update(extra_env or {})
    return subprocess.run(command, env=environment, cwd=cwd, capture_output=True, text=True, timeout=timeout)


def test_console_script_exit_code_and_message(workdir):
    path = write(workdir, "scene.yaml", MISSPELT)
    completed = run_command(["-m", "pdemfem.cli", "check", path], cwd=workdir)
    assert completed.returncode == 2
    assert completed.stderr.startswith(f"error: {path}: line 11: particles[0].insert.cuont: unknown key 'cuont'")
    assert "Traceback" not in completed.stderr


@pytest.mark.mpi
def test_bad_scene_under_mpi_prints_once_and_all_ranks_exit_2(workdir):
    path = write(workdir, "scene.yaml", OVERLAPPING)
    completed = run_command(["-m", "pdemfem.cli", "run", path, "--quiet"], ranks=2, cwd=workdir)
    assert completed.returncode == 2, completed.stderr
    assert completed.stderr.count("error: ") == 1, completed.stderr
    assert "particles 0 and 1 overlap at insertion" in completed.stderr
    assert "Traceback" not in completed.stderr
    assert sorted(p.name for p in workdir.iterdir()) == ["scene.yaml"]


RANK_LOCAL = textwrap.dedent(
    """
    import sys
    import pdemfem
    from pdemfem import cli
    from pdemfem.errors import SceneError

    def handler(arguments, comm):
        if comm.rank == 1:
            if sys.argv[1] == "user":
                raise SceneError("scene.yaml: walls[0]", "only rank 1 sees this", "none")
            raise RuntimeError("a bug on rank 1")
        comm.Barrier()  # rank 0 waits in a collective that rank 1 never joins

    cli._command_info = handler
    sys.exit(cli.main(["info"]))
    """
)


@pytest.mark.mpi
@pytest.mark.parametrize("kind, code, expected", [
    ("user", 2, "error: (rank 1 of 2; the other ranks did not fail with it) scene.yaml: walls[0]: only rank 1 sees this"),
    ("bug", 1, "[rank 1] RuntimeError: a bug on rank 1"),
])
def test_rank_local_failure_aborts_instead_of_hanging(workdir, kind, code, expected):
    script = write(workdir, "rank_local.py", RANK_LOCAL)
    completed = run_command([script, kind], ranks=2, cwd=workdir, timeout=60,
                            extra_env={"PDEMFEM_ERROR_SYNC_SECONDS": "1"})
    assert completed.returncode == code, completed.stderr
    assert expected in completed.stderr, completed.stderr
    if kind == "bug":
        assert "[rank 1] Traceback (most recent call last):" in completed.stderr


@pytest.mark.mpi
def test_launcher_finds_the_environment_commands_without_activation(tmp_path):
    """`python -m pdemfem.launch -n 2 -- pdemfem ...` through the environment's python, with its bin folder
    not on PATH: the launcher resolves `pdemfem` beside that python (mpiexec used to exit 134 printing
    nothing, its own report silenced); an unknown command is a clear exit 2."""
    bin_folder = str(Path(sys.executable).parent)
    environment = dict(os.environ)
    environment["PATH"] = os.pathsep.join(p for p in environment.get("PATH", "").split(os.pathsep)
                                          if p and Path(p).resolve() != Path(bin_folder).resolve())
    scene = Path(__file__).resolve().parents[1] / "examples" / "demo.yaml"
    ran = subprocess.run([sys.executable, "-m", "pdemfem.launch", "-n", "2", "--", "pdemfem", "check", str(scene)],
                         capture_output=True, text=True, env=environment, cwd=tmp_path, timeout=300)
    assert ran.returncode == 0 and "scene OK" in ran.stdout, (ran.returncode, ran.stdout, ran.stderr)
    missing = subprocess.run([sys.executable, "-m", "pdemfem.launch", "-n", "2", "--", "no-such-command"],
                             capture_output=True, text=True, env=environment, cwd=tmp_path, timeout=60)
    assert missing.returncode == 2 and "command 'no-such-command' not found" in missing.stderr


def test_launcher_options_are_its_own(capsys):
    """--help prints the launcher's usage; an option it does not know is named, not run as a command ('--help'
    and '--oversubscribe' were taken for the command's name: "command '--help' not found on PATH")."""
    from pdemfem import launch

    with pytest.raises(SystemExit) as shown:
        launch.main(["--help"])
    assert shown.value.code == 0 and "-n RANKS" in capsys.readouterr().out
    with pytest.raises(SystemExit) as refused:
        launch.main(["-n", "2", "--oversubscribe", "--", "true"])
    err = capsys.readouterr().err
    assert refused.value.code == 2 and "unrecognized arguments: --oversubscribe" in err and "not found" not in err


def test_check_counts_the_steps_run_takes(tmp_path):
    """end / dt = 2.5: run takes 3 steps (the last one reaches past end), and check says 3, not 2.5."""
    from pdemfem.cli import check_report

    path = tmp_path / "scene.yaml"
    path.write_text(textwrap.dedent("""\
        time: {end: 0.0025, dt: 0.001}
        materials:
          glass: {density: 2500, youngs_modulus: 5.0e6, poisson_ratio: 0.3}
        particles:
          - name: one
            material: glass
            radius: 0.001
            insert: {kind: list, positions: [[0, 0, 0]]}
        """))
    lines, _ = check_report(str(path))
    assert "steps: 3 to time.end = 0.0025 s" in lines


def _run_on_a_terminal(arguments, cwd) -> tuple:
    """(exit code, everything printed) of `pdemfem ...` on 2 ranks whose output is a terminal (a pty),
    where colouring libraries and progress bars decide to draw."""
    import pty

    command = mpiexec_command(2, [sys.executable, "-m", "pdemfem.cli", *map(str, arguments)])
    leader, follower = pty.openpty()
    process = subprocess.Popen(command, stdout=follower, stderr=follower, stdin=subprocess.DEVNULL,
                               env=process_environment(), cwd=cwd)
    os.close(follower)
    printed = b""
    while True:
        try:
            chunk = os.read(leader, 4096)
        except OSError:  # the terminal closes when the last process holding it exits
            break
        if not chunk:
            break
        printed += chunk
    os.close(leader)
    return process.wait(timeout=300), printed


@pytest.mark.mpi
def test_quiet_run_under_mpi_on_a_terminal_prints_nothing_and_no_escape_codes(workdir):
    scene = ROOT / "examples" / "collision.yaml"
    code, printed = _run_on_a_terminal(["run", scene, "-o", workdir / "quiet", "--quiet"], workdir)
    assert code == 0, printed
    assert printed == b""  # --quiet: no summary, no progress bar, no escape or carriage-return codes
    code, printed = _run_on_a_terminal(["run", scene, "-o", workdir / "loud"], workdir)
    assert code == 0 and b"results: " in printed, printed
    assert b"\x1b" not in printed  # the progress bar redraws with \r only: no ANSI escape sequences


def test_launch_environment_drops_what_a_running_mpi_process_left():
    """mpiexec started from a child of an MPI process exits 1 silently when it inherits that process's
    PMIx/singleton variables: the launch environment leaves them out and keeps everything else."""
    from pdemfem.runtime import process_environment

    inherited = {"PMIX_RANK": "0", "PMIX_SERVER_URI41": "x", "OMPI_MCA_ess": "singleton",
                 "OMPI_MCA_orte_launch": "1", "OMPI_COMM_WORLD_SIZE": "1", "PATH": "/usr/bin", "HOME": "/home/user"}
    environment = process_environment(inherited)
    assert not [key for key in environment if key.startswith(("PMIX_", "OMPI_MCA_ess", "OMPI_COMM_WORLD_"))]
    assert "OMPI_MCA_orte_launch" not in environment
    assert environment["PATH"] == "/usr/bin" and environment["HOME"] == "/home/user"

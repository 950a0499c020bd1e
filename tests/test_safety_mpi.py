"""Safety under MPI and for the PETSc options: the Python API never hangs the other ranks, never
mixes its messages with the user's, a fully clamped solid runs on several ranks, misspelt -fem_
options are reported.  Each case runs real processes (mpiexec)."""
from __future__ import annotations

import os
import shutil
import subprocess
import sys
import textwrap
from pathlib import Path

import pytest

from pdemfem.runtime import mpiexec_command, process_environment

ROOT = Path(__file__).resolve().parent.parent

# A plate meshed 8 x 8 x 1 with every face clamped: every node is constrained, the static
# operator is the identity.  Before: on 2 ranks GAMG failed its set-up (exit 3, with advice to
# add supports).
CLAMPED = """\
time: {end: 0.0002, dt: 1.0e-5}
materials:
  alu: {density: 2700, youngs_modulus: 7.0e9, poisson_ratio: 0.33}
solids:
  - name: plate
    mesh: {box: [[0, 0, 0], [0.2, 0.2, 0.02]], cells: [8, 8, 1]}
    material: alu
    fixed: [xmin, xmax, ymin, ymax, zmin, zmax]
output: {dir: results, every: 0.0001}
"""

# Grains spread over x so that 2 ranks share ghosts every step.
GRAINS = """\
time: {end: 0.004, dt: auto, dt_factor: 0.1}
materials:
  glass: {density: 2500, youngs_modulus: 5.0e6, poisson_ratio: 0.3}
particles:
  - name: grains
    material: glass
    radius: 0.001
    insert:
      kind: lattice
      region: {box: [[0, 0, 0], [0.02, 0.008, 0.008]]}
      count: 60
      jitter: 0.3
      seed: 3
walls:
  - {name: floor, kind: plane, point: [0, 0, 0], normal: [0, 0, 1], material: glass}
output: {dir: results, every: 0.001, particles: []}
"""


def run_processes(argv, ranks, cwd, timeout=120, extra_env=None):
    command = [sys.executable, *map(str, argv)]
    if ranks > 1:
        command = mpiexec_command(ranks, command)
    environment = process_environment()
    environment["PYTHONPATH"] = str(ROOT) + (":" + environment["PYTHONPATH"] if environment.get("PYTHONPATH") else "")
    environment.update(extra_env or {})
    return subprocess.run(command, env=environment, cwd=cwd, capture_output=True, text=True, timeout=timeout)


@pytest.mark.mpi
def test_fully_clamped_solid_runs_on_two_ranks(tmp_path):
    (tmp_path / "clamped.yaml").write_text(CLAMPED)
    completed = run_processes(["-m", "pdemfem.cli", "run", "clamped.yaml", "--quiet"], 2, tmp_path)
    assert completed.returncode == 0, completed.stderr
    assert (tmp_path / "results" / "history.csv").is_file()


def test_misspelt_fem_option_is_reported(tmp_path):
    (tmp_path / "clamped.yaml").write_text(CLAMPED)
    completed = run_processes(["-m", "pdemfem.cli", "run", "clamped.yaml", "--quiet",
                               "-fem_ksp_rtoll", "1e-12", "-fem_ksp_rtol", "1e-11"], 1, tmp_path)
    assert completed.returncode == 0, completed.stderr
    report = completed.stdout + completed.stderr
    assert "Option left: name:-fem_ksp_rtoll value: 1e-12" in report, report
    assert "name:-fem_ksp_rtol " not in report  # the correctly spelt option was used


@pytest.mark.mpi
def test_a_wrong_fem_option_value_is_named_once_with_exit_2(tmp_path):
    """PETSc refuses an unknown preconditioner type on every rank while the solid is set up: one message naming
    the option and PETSc's reason, no traceback, no output directory left behind."""
    (tmp_path / "clamped.yaml").write_text(CLAMPED)
    completed = run_processes(["-m", "pdemfem.cli", "run", "clamped.yaml", "--quiet", "-fem_pc_type", "nonsense"],
                              2, tmp_path)
    assert completed.returncode == 2, completed.stderr
    assert completed.stderr.count("error:") == 1 and "Traceback" not in completed.stderr, completed.stderr
    assert ("PETSc options -fem_pc_type nonsense: PETSc refused them: Unable to find requested PC type nonsense"
            in completed.stderr), completed.stderr
    assert not (tmp_path / "results").exists()


@pytest.mark.mpi
@pytest.mark.skipif(shutil.which("Xvfb") is None, reason="needs Xvfb (Debian package xvfb)")
def test_mpi_processes_leave_the_x_displays_alone(tmp_path):
    """hwloc's GL component (Debian's libhwloc-plugins) connects mpiexec and each MPI process to the X displays
    :0-:9 to look for GPUs; a virtual display `pdemfem render` started for ParaView going away during that probe
    ended the ranks of an MPI run beside it ("X connection to :0 broken", exit 1).  pdemfem's environment
    leaves the component out: an X server (logging its clients) sees no connection from a 2-rank job.  Measured
    without it: 4 connections (2 per process probing)."""
    import select

    read_end, write_end = os.pipe()
    server = subprocess.Popen(["Xvfb", "-displayfd", str(write_end), "-screen", "0", "64x64x24", "-nolisten", "tcp",
                               "-audit", "4"], pass_fds=(write_end,), stdout=subprocess.DEVNULL, stderr=subprocess.PIPE,
                              text=True)
    os.close(write_end)
    try:
        with os.fdopen(read_end) as pipe:
            assert select.select([pipe], [], [], 30)[0], "Xvfb did not start"
            number = int(pipe.readline())
        completed = run_processes(["-c", "from mpi4py import MPI; MPI.COMM_WORLD.Barrier()"], 2, tmp_path)
        assert completed.returncode == 0, completed.stderr
    finally:
        server.terminate()
        log = server.communicate(timeout=30)[1]
    if number > 9:
        pytest.skip(f"Xvfb took display :{number}, beyond the :0-:9 hwloc probes")
    assert "connected" not in log, log


API_ONE_RANK_FAILS = textwrap.dedent(
    """
    import sys
    from mpi4py import MPI
    from pdemfem.errors import OutputError
    from pdemfem.simulation import Simulation

    simulation = Simulation.from_file("grains.yaml")
    everywhere = sys.argv[1] == "all"
    original = simulation.io.write_output

    def write_output():
        if simulation.step_count > 0 and (everywhere or MPI.COMM_WORLD.rank == 1):
            raise OutputError("results/history.csv", "disk full on this rank", "free space")
        original()

    simulation.io.write_output = write_output
    try:
        simulation.run(progress=False)
    except OutputError as error:
        print(f"rank {MPI.COMM_WORLD.rank} caught: {error.problem}", flush=True)
    MPI.COMM_WORLD.Barrier()
    """
)


@pytest.mark.mpi
def test_python_api_error_on_one_rank_aborts_instead_of_hanging(tmp_path):
    # Before: rank 1's error left its script while rank 0 waited in the next collective forever
    # (the subprocess timeout here).  Now rank 1 waits PDEMFEM_ERROR_SYNC_SECONDS for the others,
    # then prints the error and aborts the job with the error's exit code.
    (tmp_path / "grains.yaml").write_text(GRAINS)
    (tmp_path / "case.py").write_text(API_ONE_RANK_FAILS)
    completed = run_processes(["case.py", "one"], 2, tmp_path, timeout=90,
                              extra_env={"PDEMFEM_ERROR_SYNC_SECONDS": "1"})
    assert completed.returncode == 2, completed.stderr
    assert "error: (rank 1 of 2; the other ranks did not fail with it" in completed.stderr, completed.stderr
    assert "disk full on this rank" in completed.stderr


@pytest.mark.mpi
def test_python_api_error_on_every_rank_is_raised_on_every_rank(tmp_path):
    (tmp_path / "grains.yaml").write_text(GRAINS)
    (tmp_path / "case.py").write_text(API_ONE_RANK_FAILS)
    completed = run_processes(["case.py", "all"], 2, tmp_path, timeout=90)
    # Held before too (every rank raises, nobody waits): the guard must not turn it into an abort.
    assert completed.returncode == 0, completed.stderr
    assert completed.stdout.count("caught: disk full on this rank") == 2, completed.stdout  # ranks' lines may interleave
    assert "rank 0 caught" in completed.stdout and "rank 1 caught" in completed.stdout


API_USER_MESSAGE = textwrap.dedent(
    """
    import numpy as np
    from mpi4py import MPI
    from pdemfem.simulation import Simulation

    world = MPI.COMM_WORLD

    def final_positions(name):
        simulation = Simulation.from_file("grains.yaml", output_dir=name)
        simulation.step(200)
        particles = simulation.particles
        rows = world.gather(np.column_stack([particles.ids, particles.positions]), root=0)
        if world.rank == 0:
            rows = np.vstack(rows)
            return rows[np.argsort(rows[:, 0])]

    reference = final_positions("reference")
    # The user's own messages in flight on their communicator, on the tags the ghost exchange
    # uses internally (71/72 at rebuilds, 81/82 every step), sent before and received after.
    requests = []
    if world.rank == 0:
        requests = [world.Isend(np.array([tag * 1000 + 7], dtype=np.int64), dest=1, tag=tag) for tag in (71, 72, 81, 82)]
    busy = final_positions("busy")
    if world.rank == 1:
        for tag in (71, 72, 81, 82):
            received = np.zeros(1, dtype=np.int64)
            world.Recv(received, source=0, tag=tag)
            assert received[0] == tag * 1000 + 7, (tag, received)
    MPI.Request.Waitall(requests)
    if world.rank == 0:
        assert np.array_equal(reference, busy), np.abs(reference - busy).max()
        print("user messages intact, simulation unchanged", flush=True)
    """
)


@pytest.mark.mpi
def test_user_messages_on_the_ghost_tags_do_not_collide(tmp_path):
    # Before: the ghost exchange ran on the user's communicator and its Irecv(tag=71) took the
    # user's message as a particle count (wrong ghosts, or a hang).
    (tmp_path / "grains.yaml").write_text(GRAINS)
    (tmp_path / "case.py").write_text(API_USER_MESSAGE)
    completed = run_processes(["case.py"], 2, tmp_path, timeout=120)
    assert completed.returncode == 0, completed.stderr
    assert "user messages intact, simulation unchanged" in completed.stdout

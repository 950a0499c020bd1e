"""Checkpoint/restart of a running simulation: exact continuation, other rank counts, errors.

The scene (restart_scenes.pile_scene): 96 grains with friction thrown against each other, plane walls
and a clamped FE plate (P1, fem_every = 2): pair, wall and FE-surface contacts with tangential
history, sub-cycling accumulators pending at odd checkpoint steps.  Checkpoints every 25 steps;
the uninterrupted run goes to step 200.  Checkpoint 25 falls amid grain-grain collisions, 175 amid
plate and wall contacts with one step of counter-forces accumulated (fem_every = 2).
"""
from __future__ import annotations

import shutil
import subprocess
import sys
from pathlib import Path

import numpy as np
import pytest

from mpi_harness import run_under_mpi

sys.path.insert(0, str(Path(__file__).parent / "mpi_cases"))

STEPS, EVERY = 200, 25
EPS = np.finfo(float).eps


def checkpoint(directory: Path, step: int) -> Path:
    return Path(directory) / "checkpoints" / f"checkpoint_{step:012d}.h5"


def run_serial(out: Path, restart=None, force=False, steps=STEPS):
    from mpi4py import MPI

    import restart_scenes
    from pdemfem.simulation import Simulation

    scene = restart_scenes.pile_scene(out, steps, EVERY, EVERY)
    with restart_scenes.cross_rank_static_solve():  # as restart_case.py: compared with 2 ranks to round-off
        simulation = Simulation.from_dict(scene, comm=MPI.COMM_WORLD, base_dir=out, restart=restart, force=force)
    simulation.run(progress=False)
    return simulation, restart_scenes.gather_state(simulation)


def assert_identical(a, b) -> None:
    assert sorted(a) == sorted(b)
    for key in a:
        assert np.array_equal(a[key], b[key]), f"{key}: max difference {np.abs(a[key] - b[key]).max()}"


# Compared on the scale of the energies they are part of, not on their own: each is a running sum of per-contact
# differences between a dashpot's work and what the contact kernels booked for it, terms of the size of the
# contacts' dissipated energy, so their round-off between rank counts is that size's (measured: a correction of
# 9.6e-8 J differing by 1.4e-19 J, 1.5e-12 of itself, where the energies reach 0.14 J).
ENERGY_SCALED = ("dashpot_correction", "dashpot_damper_work")


def assert_close(a, b, rtol) -> None:
    for key in a:
        scale = max(float(np.abs(a[key]).max()), 1e-300) if np.size(a[key]) else 1.0
        if key in ENERGY_SCALED:
            scale = max(scale, float(np.abs(a["energies"]).max()))
        difference = float(np.abs(a[key] - b[key]).max()) if np.size(a[key]) else 0.0
        print(f"{key}: max difference {difference / scale:.3g} of the scale (tolerance {rtol:.3g})")
        assert np.allclose(a[key], b[key], rtol=0, atol=rtol * scale), key


def round_off_tolerance(simulation) -> float:
    """Relative tolerance between rank counts for a run of `simulation`'s length.

    With the plate's static start converged to round-off (restart_scenes.cross_rank_static_solve), the ranks
    differ only in the order of their sums: FE rows assembled across the partition boundary, MatMult,
    ADD_VALUES of the counter-forces, the reductions.  Each step perturbs the state by ~eps of its scale, and the
    undamped linear plate carries a perturbation without growth, so it accumulates at most linearly: eps per
    step over the DEM steps and the plate's sub-steps (200 + 1209 here: 3.1e-13).  Measured: particle state
    identical, plate u and v 7.3e-14 (1 vs 2 ranks), 4.9e-14 (1 to 2), 7.0e-14 (2 to 1), plate series 1.9e-14.
    A perturbation the collisions amplify (a contact sum in another order) would exceed this: then measure the
    amplification with a one-ulp nudge as test_coupling_parallel.py does."""
    return (simulation.step_count + sum(solid.step_count for solid in simulation.solids.values())) * EPS


@pytest.fixture(scope="module")
def serial_run(tmp_path_factory):
    out = tmp_path_factory.mktemp("serial")
    simulation, state = run_serial(out)
    return out, state, round_off_tolerance(simulation)


@pytest.mark.parametrize("step", [EVERY, 175])
def test_serial_restart_is_bit_identical(serial_run, tmp_path, step):
    out, uninterrupted, _ = serial_run
    assert uninterrupted["scalars"][0] == STEPS
    shutil.copytree(out, tmp_path / "out")
    simulation, restarted = run_serial(tmp_path / "out", restart=checkpoint(tmp_path / "out", step))
    assert_identical(uninterrupted, restarted)
    # The series were continued, not restarted: all output steps present once, history rows in order.
    history = np.genfromtxt(tmp_path / "out" / "history.csv", delimiter=",", names=True)
    assert list(history["step"]) == list(range(0, STEPS + 1, EVERY))
    import h5py

    with h5py.File(tmp_path / "out" / "particles.h5", "r") as handle:
        assert sorted(int(handle[k].attrs["step"]) for k in handle if k.startswith("step_")) \
            == list(range(0, STEPS + 1, EVERY))


def test_history_after_a_restart_between_output_rows_is_the_uninterrupted_one(tmp_path):
    """A checkpoint between two history rows (output every 25 steps, checkpoint every 10: step 170): the first
    row after the restart averages the surface forces over its whole output interval, as the uninterrupted run
    does (the interval's sum so far is part of the checkpoint), so the restarted history.csv is the
    uninterrupted one byte for byte.  (Before, that row's mean_force columns averaged the 5 steps since the
    restart: 0.389 where the run had 0.0036 in a tester's pile.)"""
    from mpi4py import MPI

    import restart_scenes
    from pdemfem.simulation import Simulation

    def run(out, restart=None):
        scene = restart_scenes.pile_scene(out, STEPS, EVERY, 10)
        Simulation.from_dict(scene, comm=MPI.COMM_WORLD, base_dir=out, restart=restart).run(progress=False)
        return (out / "history.csv").read_text()

    uninterrupted = run(tmp_path / "out")
    header = uninterrupted.splitlines()[0].split(",")
    assert any(name.startswith("force_") for name in header)  # the interval-mean columns
    shutil.copytree(tmp_path / "out", tmp_path / "again")
    assert run(tmp_path / "again", restart=checkpoint(tmp_path / "again", 170)) == uninterrupted


@pytest.mark.mpi
def test_two_ranks_bit_identical_and_other_rank_counts(serial_run, tmp_path):
    serial_out, serial_state, tolerance = serial_run
    out = tmp_path / "two"
    run_under_mpi(2, "restart_case.py", out, STEPS, EVERY, tmp_path / "full.npz")
    full = dict(np.load(tmp_path / "full.npz"))
    run_under_mpi(2, "restart_case.py", out, STEPS, EVERY, tmp_path / "cont.npz",
                  "--restart", checkpoint(out, 175))
    assert_identical(full, dict(np.load(tmp_path / "cont.npz")))
    # 2 ranks agree with 1 rank to round-off, and a checkpoint continues on another rank count.
    assert_close(serial_state, full, tolerance)
    # From step 175, amid plate contacts: the surface's per-vertex state (vertices, pending counter-forces) is
    # stored in the input's node order, which a partition on another rank count does not change.
    one = tmp_path / "one"
    shutil.copytree(serial_out, one)
    run_under_mpi(2, "restart_case.py", one, STEPS, EVERY, tmp_path / "1to2.npz", "--restart", checkpoint(one, 175))
    assert_close(serial_state, dict(np.load(tmp_path / "1to2.npz")), tolerance)
    _, two_to_one = run_serial(out, restart=checkpoint(out, 175))
    assert_close(full, two_to_one, tolerance)
    # The solid series does not depend on the rank count (input numbering), so it continues across one.
    import h5py

    with h5py.File(serial_out / "plate.h5", "r") as a, h5py.File(out / "plate.h5", "r") as b:
        for name in ("mesh/points", "mesh/cells"):
            assert np.array_equal(a[name][()], b[name][()]), name
        step = f"step_{STEPS:010d}/displacements"
        assert np.allclose(a[step][()], b[step][()], rtol=0, atol=tolerance * np.abs(a[step][()]).max())


def test_checkpoint_errors(serial_run, tmp_path):
    from pdemfem.errors import CheckpointError

    out, _, _ = serial_run
    good = checkpoint(out, 100)
    with pytest.raises(CheckpointError, match="not found"):
        run_serial(tmp_path / "a", restart=tmp_path / "missing.h5")
    truncated = tmp_path / "truncated.h5"
    truncated.write_bytes(good.read_bytes()[: good.stat().st_size // 2])
    with pytest.raises(CheckpointError, match="truncated|corrupt"):
        run_serial(tmp_path / "b", restart=truncated)
    corrupt = tmp_path / "corrupt.h5"
    data = bytearray(good.read_bytes())
    import h5py

    with h5py.File(good, "r") as handle:  # flip a byte inside the particle positions
        offset = handle["particles/particles|state|rows|positions"].id.get_offset()
    data[offset + 100] ^= 0xFF
    corrupt.write_bytes(bytes(data))
    with pytest.raises(CheckpointError, match="checksum"):
        run_serial(tmp_path / "c", restart=corrupt)
    # The end time is not physics: a longer run continues without --force.
    simulation, _ = run_serial(tmp_path / "d", restart=good, steps=STEPS + EVERY)
    assert simulation.step_count == STEPS + EVERY


def test_cli_scene_change_needs_force_and_errors_exit_2(serial_run, tmp_path):
    import yaml

    import restart_scenes

    out, _, _ = serial_run
    scene = restart_scenes.pile_scene("out", STEPS + EVERY, EVERY, EVERY)
    scene["materials"]["grain"]["density"] = 2600.0  # physics changed
    path = tmp_path / "scene.yaml"
    path.write_text(yaml.safe_dump(scene))
    shutil.copytree(out, tmp_path / "out")
    good = checkpoint(tmp_path / "out", 100)
    command = [sys.executable, "-m", "pdemfem.cli", "run", str(path), "--quiet", "--restart", str(good)]
    from pdemfem.runtime import process_environment

    completed = subprocess.run(command, env=process_environment(), capture_output=True, text=True, cwd=tmp_path)
    assert completed.returncode == 2, completed.stderr
    assert "scene hash" in completed.stderr and "--force" in completed.stderr and "Traceback" not in completed.stderr
    forced = command + ["--force", "-fem_mass_ksp_rtol", "1e-9"]
    completed = subprocess.run(forced, env=process_environment(), capture_output=True, text=True, cwd=tmp_path)
    # The uninterrupted run's later checkpoints are another physics': the branch would replace them.
    assert completed.returncode == 2, completed.stderr
    assert "holds checkpoints of later steps than the restart's" in completed.stderr, completed.stderr
    later = sorted(path for path in (tmp_path / "out" / "checkpoints").glob("checkpoint_*.h5")
                   if int(path.stem.split("_")[1]) > 100)
    assert later and checkpoint(tmp_path / "out", STEPS) in later
    (tmp_path / "kept").mkdir()
    for path in later:
        path.rename(tmp_path / "kept" / path.name)
    completed = subprocess.run(forced, env=process_environment(), capture_output=True, text=True, cwd=tmp_path)
    assert completed.returncode == 0, completed.stderr
    assert checkpoint(tmp_path / "out", STEPS + EVERY).exists()


def test_moving_mesh_and_cylinder_walls_restart_bit_identical(tmp_path):
    from mpi4py import MPI

    import restart_scenes
    from pdemfem.simulation import Simulation

    def run(restart=None):
        scene = restart_scenes.add_moving_walls(restart_scenes.pile_scene(tmp_path, 150, EVERY, EVERY), tmp_path)
        simulation = Simulation.from_dict(scene, comm=MPI.COMM_WORLD, base_dir=tmp_path, restart=restart)
        simulation.run(progress=False)
        return restart_scenes.gather_state(simulation)

    uninterrupted = run()
    history = np.genfromtxt(tmp_path / "history.csv", delimiter=",", names=True)
    assert np.abs(history["force_lid_z"]).max() > 0 and np.abs(history["force_drum_x"]).max() > 0
    assert_identical(uninterrupted, run(restart=checkpoint(tmp_path, 100)))


@pytest.mark.mpi
def test_cohesive_rolling_heated_moving_restarts_bit_identical_on_one_and_two_ranks(tmp_path):
    """JKR adhesion and elastic-plastic rolling (touching flags and rolling springs in the contact
    history of pairs, plane walls and the FE surface) with heat on (temperatures, a hot wall's heat
    ledger) and the plate carried by a prescribed rigid motion (its frame's work and surface velocities):
    exact continuation on 1 and 2 ranks, and 2 ranks agree with 1 to round-off."""
    import restart_scenes
    from pdemfem.simulation import Simulation

    steps = 150
    results = {}
    for ranks in (1, 2):
        out = tmp_path / f"ranks{ranks}"
        run_under_mpi(ranks, "restart_case.py", out, steps, EVERY, tmp_path / f"full{ranks}.npz", "--cohesive",
                      "--heated", "--moving")
        run_under_mpi(ranks, "restart_case.py", out, steps, EVERY, tmp_path / f"cont{ranks}.npz", "--cohesive",
                      "--heated", "--moving", "--restart", checkpoint(out, 100))
        results[ranks] = dict(np.load(tmp_path / f"full{ranks}.npz"))
        assert_identical(results[ranks], dict(np.load(tmp_path / f"cont{ranks}.npz")))
    history = np.genfromtxt(tmp_path / "ranks1" / "history.csv", delimiter=",", names=True)
    assert history["contacts"].max() > 0
    # Heat moved: the wall gave heat and the grains' temperatures spread beyond their two starting values.
    assert history["heat_side_0"][-1] > 0
    temperatures = results[1]["field:temperatures"]
    assert len(np.unique(temperatures)) > 10 and temperatures.max() > 350.0
    # The plate's frame moved under the grains and did work on them.
    assert history["frame_work"][-1] != 0.0
    # The scene of restart_case.py, checkpoints included (a checkpoint step rebuilds canonically: row order).
    scene = restart_scenes.moving(restart_scenes.heated(restart_scenes.cohesive(
        restart_scenes.pile_scene(tmp_path / "probe", steps, EVERY, EVERY))))
    with restart_scenes.cross_rank_static_solve():
        probe = Simulation.from_dict(scene, base_dir=tmp_path)
    # Tangential spring and the force it applied (6), the rolling moment applied (3) and rolling spring (3),
    # their energy, touching flag.
    assert probe.particle_system.tables.history_width == 14
    probe.run(progress=False)  # the step counts the tolerance needs
    assert_identical(results[1], restart_scenes.gather_state(probe))
    assert_close(results[1], results[2], round_off_tolerance(probe))


@pytest.mark.mpi
def test_free_axle_restarts_bit_identical_on_two_ranks(tmp_path):
    """The plate's axis free along z (motion.carried_mass): exact continuation on 2 ranks, and 2 ranks agree
    with 1 to the round-off of the axis's force sum."""
    import restart_scenes
    from pdemfem.simulation import Simulation

    steps = 150
    out = tmp_path / "ranks2"
    run_under_mpi(2, "restart_case.py", out, steps, EVERY, tmp_path / "full2.npz", "--free-axle")
    run_under_mpi(2, "restart_case.py", out, steps, EVERY, tmp_path / "cont2.npz", "--free-axle", "--restart",
                  checkpoint(out, 100))
    two = dict(np.load(tmp_path / "full2.npz"))
    assert_identical(two, dict(np.load(tmp_path / "cont2.npz")))
    history = np.genfromtxt(out / "history.csv", delimiter=",", names=True)
    assert history["axle_height_plate"][-1] < -1e-5  # it sank
    scene = restart_scenes.free_axle(restart_scenes.pile_scene(tmp_path / "probe", steps, EVERY, EVERY))
    with restart_scenes.cross_rank_static_solve():
        probe = Simulation.from_dict(scene, base_dir=tmp_path)
    probe.run(progress=False)
    one = restart_scenes.gather_state(probe)
    # Each advance the axis takes the sum of the plate's surface-node forces (16 nodes), grouped by rank: its
    # rounding differs between rank counts by up to 16 eps of the force, on top of the eps per step the other
    # sums carry (round_off_tolerance).  Measured 3.4e-13 of the plate's u against 2.4e-13 for eps per step.
    surface_nodes = len(probe.coupled_surfaces[0].node_indices)
    assert_close(one, two, surface_nodes * round_off_tolerance(probe))

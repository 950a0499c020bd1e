"""history.csv's interval-mean contact forces, solid reactions and deflections, and `pdemfem plot`."""
from __future__ import annotations

import copy

import numpy as np
import pytest

from pdemfem import Simulation
from pdemfem.io.history import IntervalMean
from pdemfem.plot import is_constant, plot_history, read_history

STEPS_PER_ROW = 5

GRAINS = {
    "time": {"end": 1.0, "dt": 2.0e-5},  # end is set per test from the step count
    "gravity": [0, 0, -9.81],
    "materials": {"glass": {"density": 2500, "youngs_modulus": 5.0e6, "poisson_ratio": 0.3}},
    "interactions": {"default": {"restitution": 0.5, "friction": 0.5}},
    "particles": [{"name": "grains", "material": "glass", "radius": 0.001,
                   "insert": {"kind": "lattice", "region": {"box": [[0, 0, 0.00002], [0.0065, 0.0065, 0.0045]]},
                              "count": 18, "velocity": [0, 0, -0.3], "seed": 1}}],
    "walls": [{"name": "floor", "kind": "plane", "point": [0, 0, 0], "normal": [0, 0, 1], "material": "glass"}],
    "output": {"particles": [], "solids": []},
}


def grains_scene(steps: int) -> dict:
    scene = copy.deepcopy(GRAINS)
    dt = scene["time"]["dt"]
    scene["time"]["end"] = steps * dt
    scene["output"]["every"] = STEPS_PER_ROW * dt
    return scene


def test_interval_mean_repeats_and_falls_back():
    mean = IntervalMean()
    assert list(mean.take(fallback=[7.0])) == [7.0]  # no step yet: the value now
    mean.add([1.0])
    mean.add([4.0])
    assert list(mean.take(fallback=[7.0])) == [2.5]
    assert list(mean.take(fallback=[7.0])) == [2.5]  # a second row at the same step repeats the mean
    mean.add([3.0])
    assert list(mean.take(fallback=[7.0], restart=False)) == [3.0]  # a row off the schedule: the mean so far ...
    mean.add([5.0])
    assert list(mean.take(fallback=[7.0])) == [4.0]  # ... and the interval goes on to the next scheduled row


def test_a_run_extended_past_its_old_end_has_the_uninterrupted_means(tmp_path):
    """A run ending 3 steps past a row (time.end not a multiple of output.every), then extended by raising
    time.end from its end checkpoint: the rows after the old end are the uninterrupted run's.  Before, the
    old end's row started a new interval, so the next row averaged the 2 steps since it (a tester's pile:
    -21 % of the uninterrupted mean)."""
    steps = 4 * STEPS_PER_ROW
    short = 2 * STEPS_PER_ROW + 3
    uninterrupted = grains_scene(steps)
    Simulation.from_dict(uninterrupted, base_dir=tmp_path, output_dir=tmp_path / "whole").run(progress=False)
    first = grains_scene(short)
    first["time"]["end"] = short * first["time"]["dt"]
    first["output"]["every"] = uninterrupted["output"]["every"]
    first["checkpoint"] = {"every": 1.0}  # only the one at the end
    Simulation.from_dict(first, base_dir=tmp_path, output_dir=tmp_path / "extended").run(progress=False)
    extended = copy.deepcopy(uninterrupted)
    extended["checkpoint"] = first["checkpoint"]
    Simulation.from_dict(extended, base_dir=tmp_path, output_dir=tmp_path / "extended",
                         restart=tmp_path / "extended" / "checkpoints" / "latest.h5").run(progress=False)
    whole = read_history(tmp_path / "whole" / "history.csv")
    parts = read_history(tmp_path / "extended" / "history.csv")
    assert list(parts["step"]) == sorted(list(whole["step"]) + [short])  # the old end's row stays
    scheduled = np.isin(parts["step"], whole["step"])
    # The same steps summed in the same order (the interval's sum is in the checkpoint): bit for bit.
    np.testing.assert_array_equal(parts["mean_force_floor_z"][scheduled], whole["mean_force_floor_z"])
    # The old end's row: the mean of its 3 steps since the previous row (not a copy of a scheduled one).
    end_row = list(parts["step"]).index(short)
    assert parts["mean_force_floor_z"][end_row] not in whole["mean_force_floor_z"]


@pytest.mark.parametrize("every_in_steps, rows, end_stands_for", [(5.4, [0, 5, 11, 16, 22], 11),
                                                                   (5.2, [0, 5, 11, 16, 21], 10)])
def test_a_run_extended_from_an_end_at_an_interval_has_the_uninterrupted_rows(every_in_steps, rows, end_stands_for,
                                                                               tmp_path):
    """time.end = 2 output intervals, then extended to 4 by raising time.end.  The k-th row is at the step
    nearest k x every: with every = 5.4 dt the second interval's step (10.8 -> 11) is the end's, with 5.2 dt
    (10.4 -> 10) the step before the end's (11).  Either way the end's row stands for the second interval
    and the extension's rows are the uninterrupted run's, bit for bit.  Before, the rows were every
    round(every / dt) steps: the intervals drifted from their times, the end's row was decided on the times
    alone, and an extension averaged both intervals before the next row (a tester's hopper gate read +26 %)
    or only the steps since a rounded-down end (-18 %)."""
    dt = GRAINS["time"]["dt"]
    every = every_in_steps * dt
    first = copy.deepcopy(GRAINS)
    first["time"]["end"] = 2 * every
    first["output"]["every"] = every
    first["checkpoint"] = {"every": 1.0}  # only the one at the end
    Simulation.from_dict(first, base_dir=tmp_path, output_dir=tmp_path / "extended").run(progress=False)
    extended = copy.deepcopy(first)
    extended["time"]["end"] = 4 * every
    Simulation.from_dict(extended, base_dir=tmp_path, output_dir=tmp_path / "extended",
                         restart=tmp_path / "extended" / "checkpoints" / "latest.h5").run(progress=False)
    Simulation.from_dict(extended, base_dir=tmp_path, output_dir=tmp_path / "whole").run(progress=False)
    parts = read_history(tmp_path / "extended" / "history.csv")
    whole = read_history(tmp_path / "whole" / "history.csv")
    assert list(parts["step"]) == rows
    after = parts["step"] > 11
    np.testing.assert_array_equal(parts["mean_force_floor_z"][after], whole["mean_force_floor_z"][whole["step"] > 11])
    end_row = list(parts["step"]).index(11)
    second = list(whole["step"]).index(end_stands_for)
    assert parts["mean_force_floor_z"][end_row] == whole["mean_force_floor_z"][second]


def test_writes_stay_at_their_times_over_a_thousand_intervals():
    """An interval of 87.4 steps: rounded once to 87, the 1000th write came 400 steps early, and the writes
    due after the end's time (steps 87,000 to 87,348 with time.end = 1000 intervals) were never written.
    Each write at the step nearest its time: within half a step, and the last interval's is the end's."""
    from pdemfem.schedule import Schedule

    dt = 1e-5
    schedule = Schedule(87.4 * dt, dt)
    end = 1000 * 87.4 * dt
    due = [step for step in range(87_500) if schedule.due_before_end(step, end)]
    assert len(due) == 1000  # steps of the writes 0 .. 999
    assert all(abs(step - index * 87.4) <= 0.5 for index, step in enumerate(due))
    assert schedule.next_after(due[-1]) == 87_400  # the end's own step
    assert schedule.next_after(0) == 87 and schedule.next_after(87) == 175


def test_history_forces_are_means_over_the_output_interval(tmp_path):
    steps = 4 * STEPS_PER_ROW
    run = Simulation.from_dict(grains_scene(steps), base_dir=tmp_path, output_dir=tmp_path / "run")
    run.run(progress=False)
    history = read_history(tmp_path / "run" / "history.csv")
    assert list(history["step"]) == list(range(0, steps + 1, STEPS_PER_ROW))

    # The same scene stepped one step at a time, sampling the floor force after every step.
    stepped = Simulation.from_dict(grains_scene(steps), base_dir=tmp_path, output_dir=tmp_path / "stepped")
    samples = []
    for _ in range(steps):
        stepped.step(1)
        samples.append(stepped.wall_force("floor")[2])
    expected = np.mean(np.reshape(samples, (-1, STEPS_PER_ROW)), axis=1)
    # Same steps, same order of summation: equal to the last bit up to the one division (1 ulp).
    np.testing.assert_allclose(history["mean_force_floor_z"][1:], expected, rtol=4 * np.finfo(float).eps, atol=0)
    # The instantaneous column is the last sample of each interval; the grains land in this window,
    # so the impacts make the two differ (what the mean is for).
    np.testing.assert_array_equal(history["force_floor_z"][1:], np.asarray(samples)[STEPS_PER_ROW - 1::STEPS_PER_ROW])
    assert np.any(history["mean_force_floor_z"][1:] != history["force_floor_z"][1:])


PLATE = {
    "time": {"end": 1.0, "dt": 1.0e-6},
    "gravity": [0, 0, -9.81],
    "materials": {"glass": {"density": 2500, "youngs_modulus": 1.0e7, "poisson_ratio": 0.3},
                  "alu": {"density": 2700, "youngs_modulus": 7.0e10, "poisson_ratio": 0.33}},
    "particles": [{"name": "ball", "material": "glass", "radius": 0.002,
                   "insert": {"kind": "list", "positions": [[0.05, 0.01, 0.02]]}}],
    "solids": [{"name": "plate", "mesh": {"box": [[0, 0, 0], [0.1, 0.02, 0.01]], "cells": [4, 1, 1]},
                "material": "alu", "fixed": ["xmin", "xmax"], "contact": ["zmax"]}],
    "output": {"every": 5.0e-6, "particles": [], "solids": []},
}


def test_history_holds_support_reactions_and_deflection(tmp_path):
    scene = copy.deepcopy(PLATE)
    scene["time"]["end"] = 10 * scene["time"]["dt"]
    simulation = Simulation.from_dict(scene, base_dir=tmp_path, output_dir=tmp_path / "out")
    simulation.run(progress=False)
    history = read_history(tmp_path / "out" / "history.csv")
    weight = 2700 * 0.1 * 0.02 * 0.01 * 9.81
    supports = history["reaction_plate_xmin_z"] + history["reaction_plate_xmax_z"]
    # Row 0 follows the static solve (true residual below 1e-10 of the load): the supports carry the
    # plate's weight; 1e-8 leaves room for that residual summed over the support nodes.
    assert supports[0] == pytest.approx(weight, rel=1e-8)
    # Symmetric plate and load: the two supports share the weight (same residual bound).
    assert history["reaction_plate_xmin_z"][0] == pytest.approx(weight / 2, rel=1e-8)
    final = np.sqrt((simulation.solids["plate"].displacements ** 2).sum(axis=1)).max()
    assert history["max_displacement_plate"][-1] == final > 0.0


def write_history(folder, text):
    folder.mkdir()
    (folder / "history.csv").write_text(text)
    return folder


def test_plot_draws_means_reactions_and_deflections_and_skips_constants(tmp_path):
    header = ("time,step,particles,contacts,kinetic_energy,wall_work,force_floor_z,force_lid_z,"
              "mean_force_floor_z,mean_force_lid_z,reaction_plate_xmin_z,max_displacement_plate\n")
    rows = "0.0,0,10,0,0.0,0.0,0.0,0.0,0.0,0.0,1.5,0.0\n0.1,5,10,3,0.5,0.0,-2.0,0.0,-1.0,0.0,1.6,1e-6\n"
    folder = write_history(tmp_path / "run", header + rows)
    written = sorted(path.name for path in plot_history(folder))
    assert written == ["deflections.png", "energies.png", "particles.png", "reactions.png", "wall_forces.png"]

    constant = write_history(tmp_path / "still", header + rows.replace("0,3,", "0,0,").replace("-2.0,0.0,-1.0", "0.0,0.0,0.0")
                             .replace(",1.6,1e-6", ",1.5,0.0"))
    # Only the kinetic energy varies: no figure of forces, reactions, deflections or counts.
    assert sorted(path.name for path in plot_history(constant)) == ["energies.png"]


def test_is_constant_ignores_last_bit_noise_only():
    assert is_constant(np.array([0.1 + 0.2, 0.3]))
    assert not is_constant(np.array([1.0, 1.0 + 1e-9]))
    assert is_constant(np.zeros(3))


def test_run_after_steps_taken_through_the_api_writes_the_state_it_starts_from(tmp_path):
    """sim.step(n) then sim.run(): history.csv began at the first scheduled row after step n, without the state
    the run started from."""
    steps = 4 * STEPS_PER_ROW
    sim = Simulation.from_dict(grains_scene(steps), base_dir=tmp_path, output_dir=tmp_path / "run")
    sim.step(3)
    sim.run(progress=False)
    history = read_history(tmp_path / "run" / "history.csv")
    assert list(history["step"]) == [3] + list(range(STEPS_PER_ROW, steps + 1, STEPS_PER_ROW))
    # The same after a restart: the checkpoint's row is there, and the state after the steps taken since.
    scene = grains_scene(steps)
    scene["checkpoint"] = {"every": 2 * STEPS_PER_ROW * scene["time"]["dt"]}
    Simulation.from_dict(scene, base_dir=tmp_path, output_dir=tmp_path / "again").run(progress=False)
    resumed = Simulation.from_dict(scene, base_dir=tmp_path, output_dir=tmp_path / "again",
                                   restart=tmp_path / "again" / "checkpoints" / f"checkpoint_{2 * STEPS_PER_ROW:012d}.h5")
    resumed.step(3)
    resumed.run(progress=False)
    history = read_history(tmp_path / "again" / "history.csv")
    assert list(history["step"]) == [0, STEPS_PER_ROW, 2 * STEPS_PER_ROW, 2 * STEPS_PER_ROW + 3, 3 * STEPS_PER_ROW,
                                     4 * STEPS_PER_ROW]

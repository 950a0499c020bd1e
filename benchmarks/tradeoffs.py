"""Speed against accuracy, knob by knob: error against a reference versus cost, all measured in one run.

Each knob a user turns to trade accuracy for speed gets one small experiment with an independent reference
(analytic where one exists, otherwise the knob's most accurate setting) and the cost measured in the same run:

  steps_per_contact  a sphere hits a plane head-on (no gravity) with dt = t_c / N; restitution error against
                     the e the scene sets (e = 0.2 and 0.5, Hertz and linear), contact duration of the elastic
                     impact against Hertz's 2.868 (m*^2 / (R* E*^2 v))^(1/5); mean over touch phases
  contact_model      Hertz against the linear spring (stiffness derived at the expected impact speed) at
                     impacts 0.1x, 1x and 10x that speed: contact duration and peak force against Hertz's
                     analytic values; cost per step on a granular bed
  rolling_friction   a sphere rolling on a plane with rolling resistance mu_r: deceleration against
                     (5/7) mu_r g with the torque on and off; cost per step on a granular bed
  verlet_skin        a granular bed for a fixed number of steps at several skins: positions against the
                     default skin's (round-off only), cost per step, list rebuilds, listed pairs
  fe_element_mesh    a cantilever (L/h = 10, nu = 0) under a tip shear load, P1 / P2 on refined meshes:
                     tip compliance against Timoshenko's beam; cost of the static solve
  fe_mass_mesh       a clamped-free bar (nu = 0, exactly 1-D) started in its first mode shape: first axial
                     frequency against pi c / (2 L), lumped / consistent mass, P1 / P2, refined meshes; cost
                     of simulating one period (explicit steps at each case's own critical step)
  fem_every          a ball hits a clamped soft block (coupled DEM-FEM): rebound speed, peak force and block
                     indentation against fem_every = 1; cost per DEM step
  ranks              the granular bed on 1 and 2 MPI ranks: positions against 1 rank (round-off), cost per step

    python benchmarks/tradeoffs.py            # everything (~8 min on 2 shared cores)
    python benchmarks/tradeoffs.py --quick    # fewer cases and steps; what tests/test_tradeoffs_quick.py runs
    python benchmarks/tradeoffs.py --only steps_per_contact fem_every --no-plots

Prints a table per knob, writes benchmarks/results/tradeoffs.json (or --json) and, unless --no-plots, the
figures docs/img/tradeoffs_*.png (or --plots DIR).  docs/tradeoffs.md holds the tables and the advice.
Timings are wall-clock seconds on whatever machine runs this: compare them within one run only.
"""
from __future__ import annotations

import argparse
import json
import math
import os
import platform
import subprocess
import sys
import tempfile
import time
from pathlib import Path

HERE = Path(__file__).resolve().parent
REPOSITORY = HERE.parent
for folder in (HERE, REPOSITORY / "tests", REPOSITORY / "tests" / "fem"):
    if str(folder) not in sys.path:
        sys.path.insert(0, str(folder))

import numpy as np  # noqa: E402

import pdemfem  # noqa: E402,F401  (environment first)
import coupled_refinement  # noqa: E402  (the coupled impact measurement)
import settle  # noqa: E402  (the settle benchmark's bed)
from mpi_cases.coupling_scenes import ball_on_block  # noqa: E402
from mpi_cases.dem_scenes import (GLASS, STEEL, effective_modulus, hertz_duration, hertz_peak_overlap,  # noqa: E402
                                  single_sphere_on_floor, sphere_mass)
from pdemfem import Simulation  # noqa: E402
from pdemfem.scene import derived  # noqa: E402
from pdemfem.scene.loader import load_scene  # noqa: E402

DEFAULT_JSON = HERE / "results" / "tradeoffs.json"
DEFAULT_PLOTS = REPOSITORY / "docs" / "img"
WORKER_FLAG = "--ranks-worker"
KNOBS = ("steps_per_contact", "contact_model", "rolling_friction", "verlet_skin", "fe_element_mesh",
         "fe_mass_mesh", "fem_every", "ranks")

# ----------------------------------------------------------------------------- settings (full / quick)
FULL = {
    "steps_per_contact": [3, 6, 14, 28, 56, 159, 300],
    "touch_phases": 8,
    "restitutions": [0.2, 0.5],
    "model_speeds": [0.1, 1.0, 10.0],
    "rolling_steps": 4000,
    "bed_particles": 10000,
    "bed_pre_steps": 3000,
    "bed_steps": 1000,
    "skins": [0.1, 0.2, 0.3, 0.5, 1.0],
    "checkpoints": [500, 700, 1000, 1500, 2000, 3000],   # steps (within bed_pre_steps) where positions are compared
    "cantilever_p1": [(10, 1, 1), (20, 2, 2), (40, 4, 4), (80, 8, 8)],
    "cantilever_p2": [(5, 1, 1), (10, 1, 1), (20, 2, 2), (40, 4, 4)],
    "bar_cells": [4, 8, 16, 32],
    "fem_every": [1, 2, 5, 10],
    "fem_every_cells": 8,
    "ranks": [1, 2],
}
QUICK = {
    "steps_per_contact": [3, 14, 159],
    "touch_phases": 2,
    "restitutions": [0.2],
    "model_speeds": [0.1, 1.0, 10.0],
    "rolling_steps": 1000,
    "bed_particles": 500,
    "bed_pre_steps": 1500,
    "bed_steps": 300,
    "skins": [0.1, 0.3, 1.0],
    "checkpoints": [500, 1000],
    "cantilever_p1": [(10, 1, 1), (20, 2, 2)],
    "cantilever_p2": [(5, 1, 1), (10, 1, 1)],
    "bar_cells": [4, 8],
    "fem_every": [1, 2, 5, 10],
    "fem_every_cells": 2,
    "ranks": [1, 2],
}

IMPACT_RADIUS = 1.0e-3
IMPACT_SPEED = 1.0
APPROACH_STEPS = 4.0     # steps of free flight before the touch (plus the touch phase, a fraction of a step)


# ============================================================================= DEM: one impact
def _impact_scene(model: str, restitution: float, speed: float, expected_speed: float, dt: float, phase: float) -> dict:
    """A glass sphere (r = 1 mm) flying at `speed` onto a steel plane, no gravity, first touch `phase` into a step."""
    return single_sphere_on_floor(radius=IMPACT_RADIUS, material=GLASS, wall_material=STEEL, velocity=(0.0, 0.0, -speed),
                                  height=IMPACT_RADIUS + (APPROACH_STEPS + phase) * speed * dt, dt=dt, model=model,
                                  restitution=restitution, expected_impact_speed=expected_speed)


def contact_time(model: str, speed: float, expected_speed: float) -> float:
    """The contact duration `pdemfem check` states for this impact (Hertz, or pi sqrt(m*/k) of the derived k)."""
    scene, _ = load_scene(_impact_scene(model, 1.0, speed, expected_speed, 1e-6, 0.0), base_dir=Path("."))
    return derived.contact_duration(scene, speed).particle_wall


def impact(model: str, restitution: float, speed: float, steps_per_contact: float, phase: float,
           expected_speed: float = None) -> dict:
    """Run one impact; returns the restitution (rebound / impact speed), the contact duration (overlap
    crossings, interpolated), the peak wall force (sampled), the steps taken and the wall time."""
    expected_speed = speed if expected_speed is None else expected_speed
    dt = contact_time(model, speed, expected_speed) / steps_per_contact
    sim = Simulation.from_dict(_impact_scene(model, restitution, speed, expected_speed, dt, phase))
    times, overlaps, peak = [0.0], [IMPACT_RADIUS - sim.particles.positions[0, 2]], 0.0
    started = time.perf_counter()
    steps = 0
    while True:
        sim.step()
        steps += 1
        times.append(sim.time)
        overlaps.append(IMPACT_RADIUS - sim.particles.positions[0, 2])
        peak = max(peak, abs(float(sim.wall_force("floor")[2])))
        if overlaps[-1] < 0.0 < max(overlaps):
            break
        if steps > 100 * steps_per_contact + 100:
            raise RuntimeError("the sphere did not leave the floor")
    seconds = time.perf_counter() - started
    overlaps = np.array(overlaps)
    inside = np.nonzero(overlaps > 0.0)[0]
    first, last = inside[0], inside[-1]

    def crossing(k0, k1):
        return times[k0] + (times[k1] - times[k0]) * overlaps[k0] / (overlaps[k0] - overlaps[k1])

    duration = crossing(last, last + 1) - crossing(first - 1, first)
    # No gravity: after the clamped force has vanished the sphere flies at constant speed.
    rebound = float(sim.particles.velocities[0, 2])
    return {"restitution": rebound / speed, "duration": duration, "peak_force": peak, "steps": steps,
            "seconds": seconds, "dt": dt}


def hertz_reference(speed: float) -> dict:
    """Analytic elastic Hertz impact of the test sphere on the plane: duration, peak overlap and force."""
    mass, e_star = sphere_mass(GLASS, IMPACT_RADIUS), effective_modulus(GLASS, STEEL)
    overlap = hertz_peak_overlap(mass, IMPACT_RADIUS, e_star, speed)
    return {"duration": hertz_duration(mass, IMPACT_RADIUS, e_star, speed), "max_overlap": overlap,
            "peak_force": 4.0 / 3.0 * e_star * math.sqrt(IMPACT_RADIUS) * overlap**1.5}


def knob_steps_per_contact(settings: dict, log) -> dict:
    phases = [(k + 0.5) / settings["touch_phases"] for k in range(settings["touch_phases"])]
    reference = hertz_reference(IMPACT_SPEED)
    rows = []
    for steps in settings["steps_per_contact"]:
        row = {"steps_per_contact": steps}
        for model in ("hertz_mindlin", "linear_spring_dashpot"):
            for restitution in settings["restitutions"]:
                runs = [impact(model, restitution, IMPACT_SPEED, steps, phase) for phase in phases]
                errors = [run["restitution"] / restitution - 1.0 for run in runs]
                row[f"{model}_e{restitution}_error"] = float(np.mean(errors))
                row[f"{model}_e{restitution}_spread"] = [float(min(errors)), float(max(errors))]
                if model == "hertz_mindlin" and restitution == settings["restitutions"][0]:
                    # the fastest of the touch phases (same work each): sharing the machine only slows a run down
                    row["seconds_per_contact"] = float(np.min([run["seconds"] for run in runs]))
                    row["steps_per_impact"] = float(np.mean([run["steps"] for run in runs]))
        elastic = [impact("hertz_mindlin", 1.0, IMPACT_SPEED, steps, phase) for phase in phases]
        row["hertz_duration_error"] = float(np.mean([run["duration"] for run in elastic]) / reference["duration"] - 1.0)
        row["hertz_elastic_restitution_error"] = float(np.mean([run["restitution"] for run in elastic]) - 1.0)
        rows.append(row)
        log("  N = {:4d}: ".format(steps) + "  ".join(
            f"{key.replace('_spring_dashpot', '').replace('_mindlin', '').replace('_error', '')} {value:+.2%}"
            for key, value in row.items() if key.endswith("_error")) + f"  {row['seconds_per_contact'] * 1e3:.1f} ms/impact")
    auto = {str(e): derived.steps_per_contact_required("hertz_mindlin", e) for e in settings["restitutions"]}
    return {"reference": "restitution: the e the scene sets; duration: Hertz's analytic elastic impact",
            "impact_speed": IMPACT_SPEED, "touch_phases": len(phases), "auto_steps_per_contact": auto, "rows": rows}


def knob_contact_model(settings: dict, bed_costs: dict, log) -> dict:
    """Linear spring calibrated at 1 m/s against Hertz at other impact speeds (elastic, 200 steps per contact)."""
    rows = []
    for speed in settings["model_speeds"]:
        reference = hertz_reference(speed)
        row = {"speed": speed}
        for model in ("hertz_mindlin", "linear_spring_dashpot"):
            run = impact(model, 1.0, speed, 200, 0.5, expected_speed=IMPACT_SPEED)
            row[f"{model}_duration_error"] = run["duration"] / reference["duration"] - 1.0
            row[f"{model}_peak_force_error"] = run["peak_force"] / reference["peak_force"] - 1.0
        rows.append(row)
        log(f"  impact {speed:5.2f} m/s (calibrated at {IMPACT_SPEED} m/s): duration hertz "
            f"{row['hertz_mindlin_duration_error']:+.2%} linear {row['linear_spring_dashpot_duration_error']:+.2%}; "
            f"peak force hertz {row['hertz_mindlin_peak_force_error']:+.2%} linear "
            f"{row['linear_spring_dashpot_peak_force_error']:+.2%}")
    return {"reference": "Hertz's analytic elastic impact at each speed; the linear stiffness is derived at "
                         f"{IMPACT_SPEED} m/s", "rows": rows, "bed_cost": bed_costs}


# ============================================================================= DEM: rolling resistance
def knob_rolling_friction(settings: dict, bed_costs: dict, log) -> dict:
    """A sphere rolling on a plane: deceleration against (5/7) mu_r g (tests/test_dem_rolling.py's case)."""
    gravity, v0, mu, mu_r = 9.81, 0.2, 0.5, 0.05
    deceleration = 5.0 / 7.0 * mu_r * gravity
    stop_time = v0 / deceleration
    mass, e_star = sphere_mass(GLASS, IMPACT_RADIUS), effective_modulus(GLASS, STEEL)
    resting = (mass * gravity / (4.0 / 3.0 * e_star * math.sqrt(IMPACT_RADIUS))) ** (2.0 / 3.0)
    rows = []
    for on in (True, False):
        steps = settings["rolling_steps"]
        dt = 0.5 * stop_time / steps   # the first half of the deceleration (the test's window)
        scene = single_sphere_on_floor(radius=IMPACT_RADIUS, material=GLASS, wall_material=STEEL,
                                       velocity=(v0, 0.0, 0.0), angular_velocity=(0.0, v0 / (IMPACT_RADIUS - resting), 0.0),
                                       height=IMPACT_RADIUS - resting, dt=dt, restitution=0.5, friction=mu,
                                       rolling_friction=mu_r if on else 0.0, gravity=(0.0, 0.0, -gravity),
                                       expected_impact_speed=0.1)
        sim = Simulation.from_dict(scene)
        times, speeds, start_x = [], [], float(sim.particles.positions[0, 0])
        started = time.perf_counter()
        chunk = max(1, steps // 50)
        for _ in range(steps // chunk):
            sim.step(chunk)
            times.append(sim.time)
            speeds.append(float(sim.particles.velocities[0, 0]))
        seconds = time.perf_counter() - started
        slope = float(np.polyfit(times, speeds, 1)[0])
        distance = float(sim.particles.positions[0, 0]) - start_x
        exact_distance = v0 * sim.time - 0.5 * deceleration * sim.time**2
        row = {"rolling_friction": mu_r if on else 0.0, "deceleration": -slope,
               "deceleration_error": -slope / deceleration - 1.0, "distance_error": distance / exact_distance - 1.0,
               "seconds_per_step": seconds / steps,
               "bed_seconds_per_step": bed_costs["rolling_on" if on else "rolling_off"]["seconds_per_step"],
               "bed_cpu_seconds_per_step": bed_costs["rolling_on" if on else "rolling_off"]["cpu_seconds_per_step"]}
        rows.append(row)
        log(f"  rolling resistance {'on ' if on else 'off'}: deceleration {-slope:.4f} m/s^2 "
            f"({row['deceleration_error']:+.2%}), distance over {sim.time:.3f} s {row['distance_error']:+.2%}, "
            f"bed {row['bed_seconds_per_step'] * 1e3:.2f} ms/step")
    return {"reference": f"analytic (5/7) mu_r g = {deceleration:.5f} m/s^2 for mu_r = {mu_r} (rolling without slip)",
            "speed": v0, "rows": rows}


# ============================================================================= DEM: the granular bed
BED_IMPACT_SPEED = 0.5   # the linear model's calibration speed in the bed [m/s]


def bed_linear_stiffness() -> float:
    """The k_n the linear model derives for two bed spheres at BED_IMPACT_SPEED (Hertz's peak overlap)."""
    glass = {"density": settle.DENSITY, "youngs_modulus": settle.YOUNGS_MODULUS, "poisson_ratio": settle.POISSON_RATIO}
    mass = 0.5 * sphere_mass(glass, settle.RADIUS)
    overlap = hertz_peak_overlap(mass, 0.5 * settle.RADIUS, effective_modulus(glass, glass), BED_IMPACT_SPEED)
    return mass * BED_IMPACT_SPEED**2 / overlap**2


def bed_scene(particles: int, skin_factor: float = 0.3, model: str = "hertz_mindlin", rolling_friction: float = 0.0,
              normal_stiffness: float = None) -> dict:
    """benchmarks/settle.py's scene (glass, d = 2 mm, e = 0.5, mu = 0.5, dt = 2e-5 s, a jittered lattice of
    spacing 2.4 mm collapsing into a five-wall box): timed while the bed forms (collisions, contacts opening
    and closing, particles crossing the list's skin)."""
    scene = settle.scene_dict(particles)
    scene["neighbors"] = {"skin": skin_factor * settle.RADIUS}
    scene["interactions"]["default"].update(model=model, rolling_friction=rolling_friction)
    if model == "linear_spring_dashpot":
        scene["time"]["expected_impact_speed"] = BED_IMPACT_SPEED
    if normal_stiffness is not None:
        scene["interactions"]["default"]["normal_stiffness"] = normal_stiffness
    return scene


def _gathered_positions(sim, comm):
    """Positions by particle id on rank 0 (None elsewhere)."""
    particles = sim.particles
    gathered = comm.gather((particles.ids, particles.positions), root=0)
    if comm.rank != 0:
        return None
    ids = np.concatenate([part[0] for part in gathered])
    return np.concatenate([part[1] for part in gathered])[np.argsort(ids)]


def run_bed(scene: dict, pre_steps: int, steps: int, comm=None, nudge: bool = False, checkpoints=()) -> dict:
    """Build, take pre_steps untimed, time `steps`; returns wall seconds per step (max over ranks), rebuilds,
    listed pairs and contacts at the end, and (rank 0) the positions by particle id at the end and at each
    checkpoint (a step count within the untimed pre_steps).
    nudge: move one particle by one unit in the last place of its x at the start (the yardstick of round-off)."""
    from mpi4py import MPI

    comm = comm or MPI.COMM_WORLD
    snapshots = {}
    with tempfile.TemporaryDirectory(prefix="tradeoffs-bed-") as scratch:
        sim = Simulation.from_dict(scene, comm=comm, output_dir=scratch)
        if nudge and sim.particle_system.state.owned_count:
            positions = sim.particle_system.state.positions
            positions[0, 0] = np.nextafter(positions[0, 0], np.inf)
        done = 0
        for mark in sorted(mark for mark in checkpoints if mark <= pre_steps):
            sim.step(mark - done)
            done = mark
            snapshots[mark] = _gathered_positions(sim, comm)
        sim.step(pre_steps - done)
        system = sim.particle_system
        original = system._rebuild
        counter = {"rebuilds": 0}

        def counted(*args, **kwargs):
            counter["rebuilds"] += 1
            return original(*args, **kwargs)

        system._rebuild = counted
        comm.Barrier()
        started, cpu_started = time.perf_counter(), time.process_time()
        sim.step(steps)
        cpu = comm.allreduce(time.process_time() - cpu_started, op=MPI.MAX)
        elapsed = comm.allreduce(time.perf_counter() - started, op=MPI.MAX)
        system._rebuild = original
        pairs = comm.allreduce(int(system.neighbors.pair_count))
        contacts = sim.contact_count()
        snapshots[pre_steps + steps] = _gathered_positions(sim, comm)
    result = {"seconds_per_step": elapsed / steps, "cpu_seconds_per_step": cpu / steps, "rebuilds": comm.allreduce(counter["rebuilds"], op=MPI.MAX),
              "listed_pairs": pairs, "contacts": contacts, "steps": steps, "pre_steps": pre_steps}
    if comm.rank == 0:
        result["positions"] = snapshots[pre_steps + steps]
        result["snapshots"] = snapshots
    return result


def _position_difference(run: dict, reference: dict) -> float:
    """Largest position difference over all particles at the end, in particle radii."""
    return float(np.abs(run["positions"] - reference["positions"]).max() / settle.RADIUS)


def _difference_growth(run: dict, reference: dict) -> dict:
    """Largest position difference [radii] at every step both runs were sampled at."""
    return {str(step): float(np.abs(run["snapshots"][step] - reference["snapshots"][step]).max() / settle.RADIUS)
            for step in sorted(run["snapshots"]) if step in reference["snapshots"]}


def bed_costs(settings: dict, log) -> dict:
    """Cost per step of the bed for the contact model and rolling knobs (same scene, same steps)."""
    costs = {}
    variants = {"hertz": {}, "linear": {"model": "linear_spring_dashpot"},
                "linear_given_stiffness": {"model": "linear_spring_dashpot", "normal_stiffness": bed_linear_stiffness()},
                "rolling_on": {"rolling_friction": 0.05}}
    for name, keys in variants.items():
        run = run_bed(bed_scene(settings["bed_particles"], **keys), settings["bed_pre_steps"], settings["bed_steps"])
        costs[name] = {key: run[key] for key in ("seconds_per_step", "cpu_seconds_per_step", "rebuilds", "listed_pairs",
                                                 "contacts")}
        log(f"  bed ({settings['bed_particles']} spheres) {name:22s}: {run['seconds_per_step'] * 1e3:.3f} ms/step "
            f"({run['cpu_seconds_per_step'] * 1e3:.3f} ms CPU), {run['contacts']} contacts")
    costs["rolling_off"] = costs["hertz"]
    return costs


def knob_verlet_skin(settings: dict, log) -> dict:
    runs = {}
    for skin in settings["skins"]:
        runs[skin] = run_bed(bed_scene(settings["bed_particles"], skin), settings["bed_pre_steps"], settings["bed_steps"],
                             checkpoints=settings["checkpoints"])
    reference = runs[0.3]
    nudged = run_bed(bed_scene(settings["bed_particles"], 0.3), settings["bed_pre_steps"], settings["bed_steps"], nudge=True,
                     checkpoints=settings["checkpoints"])
    roundoff = _position_difference(nudged, reference)
    roundoff_growth = _difference_growth(nudged, reference)
    log(f"  round-off yardstick: skin 0.3 r with one particle moved by 1 ulp at the start: "
        + ", ".join(f"{value:.1e}" for value in roundoff_growth.values()) + f" r at steps {', '.join(roundoff_growth)}")
    rows = []
    for skin, run in runs.items():
        row = {"skin_radii": skin, "seconds_per_step": run["seconds_per_step"],
               "cpu_seconds_per_step": run["cpu_seconds_per_step"], "rebuilds": run["rebuilds"],
               "listed_pairs": run["listed_pairs"], "contacts": run["contacts"],
               "position_difference_radii": _position_difference(run, reference),
               "position_difference_growth": _difference_growth(run, reference)}
        rows.append(row)
        log(f"  skin {skin:4.2f} r: {run['seconds_per_step'] * 1e3:.3f} ms/step ({run['cpu_seconds_per_step'] * 1e3:.3f} "
            f"ms CPU), {run['rebuilds']} rebuilds, "
            f"{run['listed_pairs']} listed pairs, positions vs skin 0.3 r: "
            + ", ".join(f"{value:.1e}" for value in row["position_difference_growth"].values()))
    return {"reference": "the default skin (0.3 r): the same physics, other summation order",
            "particles": settings["bed_particles"], "steps": settings["bed_steps"],
            "pre_steps": settings["bed_pre_steps"], "one_ulp_difference_radii": roundoff,
            "one_ulp_difference_growth": roundoff_growth, "rows": rows}


# ============================================================================= ranks (subprocesses)
def ranks_worker(path: str, particles: int, pre_steps: int, steps: int, checkpoints) -> None:
    from mpi4py import MPI

    tiny = bed_scene(27 * MPI.COMM_WORLD.size)
    with tempfile.TemporaryDirectory(prefix="tradeoffs-tiny-") as scratch:
        Simulation.from_dict(tiny, output_dir=scratch).step(3)   # compile (or load) the kernels untimed
    run = run_bed(bed_scene(particles), pre_steps, steps, checkpoints=checkpoints)
    if MPI.COMM_WORLD.rank == 0:
        snapshots = run.pop("snapshots")
        run.pop("positions")
        np.savez(path, **{f"step{step}": value for step, value in snapshots.items()},
                 summary=json.dumps(dict(run, ranks=MPI.COMM_WORLD.size)))


def launch_ranks_worker(command: list) -> None:
    """Run one rank count's worker; its output is shown when it fails (Open MPI's own report is silenced).

    Run this benchmark from a process that has not initialised MPI itself, or with that process's startup
    environment (os.environ): an MPI singleton puts its PMIx variables into the C environment its children
    inherit, and an mpiexec started under them exits 1 without a word."""
    completed = subprocess.run(command, cwd=REPOSITORY, env=dict(os.environ, PYTHONPATH=str(REPOSITORY)),
                               capture_output=True, text=True)
    if completed.returncode != 0:
        raise RuntimeError(f"{' '.join(command)} exited {completed.returncode}\n--- stdout\n{completed.stdout}\n"
                           f"--- stderr\n{completed.stderr}")


def knob_ranks(settings: dict, log) -> dict:
    runs = {}
    with tempfile.TemporaryDirectory(prefix="tradeoffs-ranks-") as scratch:
        for ranks in settings["ranks"]:
            path = os.path.join(scratch, f"ranks{ranks}.npz")
            command = [sys.executable, "-m", "pdemfem.launch", "-n", str(ranks), "--", sys.executable,
                       str(Path(__file__).resolve()), WORKER_FLAG, path, str(settings["bed_particles"]),
                       str(settings["bed_pre_steps"]), str(settings["bed_steps"]),
                       ",".join(map(str, settings["checkpoints"]))]
            launch_ranks_worker(command)
            with np.load(path) as stored:
                snapshots = {int(key[4:]): stored[key] for key in stored.files if key.startswith("step")}
                runs[ranks] = dict(json.loads(str(stored["summary"])), snapshots=snapshots,
                                   positions=snapshots[max(snapshots)])
    reference = runs[settings["ranks"][0]]
    rows = []
    for ranks, run in runs.items():
        row = {"ranks": ranks, "seconds_per_step": run["seconds_per_step"], "contacts": run["contacts"],
               "position_difference_radii": _position_difference(run, reference),
               "position_difference_growth": _difference_growth(run, reference),
               "speedup": reference["seconds_per_step"] / run["seconds_per_step"]}
        rows.append(row)
        log(f"  {ranks} rank(s): {run['seconds_per_step'] * 1e3:.3f} ms/step (speed-up {row['speedup']:.2f}), "
            "positions vs 1 rank: " + ", ".join(f"{value:.1e}" for value in row["position_difference_growth"].values()))
    return {"reference": "1 rank: the same physics, other summation order across the subdomain boundary",
            "particles": settings["bed_particles"], "steps": settings["bed_steps"], "rows": rows}


# ============================================================================= FE: element and mesh (static)
def cantilever_compliance(element: str, cells) -> dict:
    """Tip compliance of a clamped L/h = 10 beam (nu = 0) under a uniform shear traction on its free end,
    against Timoshenko (kappa = 5/6); the same case as tests/fem/test_fem_static.py."""
    from fem_helpers import box_solid, material

    E, L, P, nu = 1000.0, 10.0, 1.0, 0.0
    started = time.perf_counter()
    solid = box_solid((0, 0, 0), (L, 1, 1), cells, material(E=E, nu=nu), element=element, fixed=["xmin"],
                      tractions=[{"group": "xmax", "traction": [0.0, 0.0, -P]}])
    built = time.perf_counter()
    solid.static_solve()
    solved = time.perf_counter()
    deflection = solid.load_vec.dot(solid.displacement_vec) / P
    inertia, area, shear = 1.0 / 12.0, 1.0, E / (2 * (1 + nu))
    timoshenko = P * L**3 / (3 * E * inertia) + P * L / (10 * (1 + nu) / (12 + 11 * nu) * shear * area)
    return {"element": element, "cells": list(cells), "dofs": 3 * solid.n_global_nodes,
            "error": deflection / timoshenko - 1.0, "setup_seconds": built - started, "solve_seconds": solved - built}


def knob_fe_element_mesh(settings: dict, log) -> dict:
    rows = []
    for element, meshes in (("P1", settings["cantilever_p1"]), ("P2", settings["cantilever_p2"])):
        for cells in meshes:
            row = cantilever_compliance(element, cells)
            rows.append(row)
            log(f"  {element} {'x'.join(map(str, cells)):>8s}: {row['dofs']:6d} DOF, tip deflection "
                f"{row['error']:+.2%}, static solve {row['solve_seconds']:.3f} s")
    return {"reference": "Timoshenko beam (kappa = 5/6), L/h = 10, nu = 0", "rows": rows}


# ============================================================================= FE: mass and mesh (dynamic)
def bar_frequency(element: str, mass: str, cells: int, periods: float = 3.0) -> dict:
    """First axial frequency of a clamped-free steel bar (L = 1 m, 0.1 x 0.1 m, nu = 0: the 1-D bar exactly),
    started from rest in the continuum mode shape u_x = A sin(pi x / (2 L)); measured from the zero crossings
    of the tip's mean displacement, stepped at the case's own critical step (what `dt: auto` takes)."""
    from fem_helpers import box_solid, material

    E, rho, L = 2e11, 7800.0, 1.0
    exact = math.pi / 2 * math.sqrt(E / rho) / L
    solid = box_solid((0, 0, 0), (L, 0.1, 0.1), (cells, 1, 1), material(E=E, nu=0.0, rho=rho), element=element,
                      mass=mass, fixed=["xmin"])
    x = solid.reference_positions[:, 0]
    displacement = np.zeros((solid.n_owned_nodes, 3))
    displacement[:, 0] = 1e-6 * np.sin(math.pi * x / (2 * L))
    solid.set_state(displacement, np.zeros_like(displacement))
    tip = np.isclose(x, L)
    dt = solid.critical_time_step()
    steps = int(math.ceil(periods * 2 * math.pi / exact / dt))
    history, step_seconds = [float(solid.displacements[tip, 0].mean())], []
    for _ in range(steps):
        started = time.perf_counter()
        solid.step(dt)
        step_seconds.append(time.perf_counter() - started)
        history.append(float(solid.displacements[tip, 0].mean()))
    # the median step: every step does the same work, and sharing the machine only slows some of them down
    seconds = float(np.median(step_seconds)) * steps
    z = np.array(history)
    t = dt * np.arange(len(z))
    k = np.flatnonzero(np.sign(z[:-1]) != np.sign(z[1:]))
    crossings = t[k] - z[k] * dt / (z[k + 1] - z[k])
    omega = math.pi / float(np.mean(np.diff(crossings)))
    return {"element": element, "mass": mass, "cells": cells, "dofs": 3 * solid.n_global_nodes,
            "error": omega / exact - 1.0, "dt": dt, "steps_per_period": 2 * math.pi / exact / dt,
            "seconds_per_step": seconds / steps, "seconds_per_period": seconds / steps * 2 * math.pi / exact / dt}


def knob_fe_mass_mesh(settings: dict, log) -> dict:
    rows = []
    for element in ("P1", "P2"):
        for mass in ("lumped", "consistent"):
            for cells in settings["bar_cells"]:
                row = bar_frequency(element, mass, cells)
                rows.append(row)
                log(f"  {element} {mass:10s} {cells:3d} cells: {row['dofs']:5d} DOF, frequency {row['error']:+.3%}, "
                    f"{row['steps_per_period']:.0f} steps/period, {row['seconds_per_period'] * 1e3:.1f} ms/period")
    return {"reference": "analytic pi c / (2 L) of the clamped-free bar", "rows": rows}


# ============================================================================= coupling: fem_every
TIMING_CHUNK = 10   # steps per timed chunk: a multiple of every fem_every measured
def knob_fem_every(settings: dict, log) -> dict:
    """Ball (R = 0.2 m, e = 0.2) onto a clamped soft block (E = 1e8, 10x the ball; P1) at 2.4 m/s, no gravity;
    coupled_refinement.measure_impact measures the rebound, peak force and indentation."""
    cells = settings["fem_every_cells"]
    rows, reference = [], None
    with tempfile.TemporaryDirectory(prefix="tradeoffs-fem-every-") as scratch:
        for every in settings["fem_every"]:
            scene = ball_on_block(height=0.701, speed=2.4, block_modulus=1e8, fem_every=every,
                                  cells=(cells, cells, max(1, cells // 2)))
            scene["gravity"] = [0.0, 0.0, 0.0]   # the rebound is then the sphere's speed after the pulse
            measured = coupled_refinement.measure_impact(scene, scratch)
            steps = len(measured["times"]) - 1
            # Cost: the same steps again in chunks of TIMING_CHUNK (a multiple of every k, so each chunk holds the
            # same FE work); the median chunk, since sharing the machine only slows some chunks down.
            sim = Simulation.from_dict(scene, output_dir=scratch)
            effective = sim.coupling.fem_every   # run may lower k (the held-force limit)
            chunks = []
            for _ in range(max(1, steps // TIMING_CHUNK)):
                started = time.perf_counter()
                sim.step(TIMING_CHUNK)
                chunks.append(time.perf_counter() - started)
            measured["seconds"] = float(np.median(chunks)) / TIMING_CHUNK * steps
            row = {"fem_every": every, "effective_fem_every": effective, "rebound": measured["invariant"], "peak_force": measured["sampled_peak_force"],
                   "indentation": measured["block_indentation"], "fem_substeps": measured["fem_substeps"],
                   "seconds_per_step": measured["seconds"] / steps}
            reference = reference or row
            for key in ("rebound", "peak_force", "indentation"):
                row[f"{key}_error"] = row[key] / reference[key] - 1.0
            rows.append(row)
            log(f"  fem_every {every:2d}: rebound {row['rebound']:.5f} m/s ({row['rebound_error']:+.2e}), peak "
                f"{row['peak_force']:.5g} N ({row['peak_force_error']:+.2e}), indentation {row['indentation_error']:+.2e}, "
                f"{row['seconds_per_step'] * 1e3:.3f} ms/step ({row['fem_substeps']} FE sub-steps per advance)")
    return {"reference": "fem_every = 1 (the same scene)", "cells": [cells, cells, max(1, cells // 2)], "rows": rows}


# ============================================================================= plots
def draw(results: dict, folder: Path) -> list:
    """Error against cost, one figure per family of knobs: docs/img/tradeoffs_{dem,fem,cost}.png."""
    from pdemfem.plot import agg_pyplot

    plt = agg_pyplot()

    knobs = results["knobs"]
    folder.mkdir(parents=True, exist_ok=True)
    written = []

    def save(figure, name):
        path = folder / f"tradeoffs_{name}.png"
        figure.tight_layout()
        figure.savefig(path, dpi=72)
        plt.close(figure)
        written.append(path)

    if "steps_per_contact" in knobs or "contact_model" in knobs:
        figure, axes = plt.subplots(1, 2, figsize=(10, 3.8))
        if "steps_per_contact" in knobs:
            rows = knobs["steps_per_contact"]["rows"]
            steps = [row["steps_per_contact"] for row in rows]
            for key in rows[0]:
                if key.endswith("_error") and not key.startswith("hertz_elastic"):
                    label = key.replace("_spring_dashpot", "").replace("_mindlin", "").replace("_error", "")
                    label = label.replace("_e", " e = ").replace("hertz_duration", "Hertz duration (e = 1)")
                    axes[0].loglog(steps, [max(abs(row[key]), 1e-5) for row in rows], "o-", label=label)
            axes[0].axhline(0.01, color="k", lw=0.6, ls=":")
            axes[0].set_xlabel("steps per contact N = t_c / dt  (cost per simulated second ~ N)")
            axes[0].set_ylabel("|error|")
            axes[0].set_title("time step: restitution and duration")
            axes[0].legend(fontsize=7)
        if "contact_model" in knobs:
            rows = knobs["contact_model"]["rows"]
            speeds = [row["speed"] for row in rows]
            for model, marker in (("hertz_mindlin", "o"), ("linear_spring_dashpot", "s")):
                for quantity, style in (("duration", "-"), ("peak_force", "--")):
                    axes[1].plot(speeds, [100 * row[f"{model}_{quantity}_error"] for row in rows], style, marker=marker,
                                 label=f"{model.split('_')[0]} {quantity.replace('_', ' ')}")
            axes[1].set_xscale("log")
            axes[1].set_xlabel("impact speed [m/s] (linear stiffness derived at 1 m/s)")
            axes[1].set_ylabel("error vs Hertz [%]")
            axes[1].set_title("contact model")
            axes[1].legend(fontsize=7)
        save(figure, "dem")

    if "fe_element_mesh" in knobs or "fe_mass_mesh" in knobs:
        figure, axes = plt.subplots(1, 2, figsize=(10, 3.8))
        if "fe_element_mesh" in knobs:
            rows = knobs["fe_element_mesh"]["rows"]
            for element in ("P1", "P2"):
                chosen = [row for row in rows if row["element"] == element]
                axes[0].loglog([row["dofs"] for row in chosen], [max(abs(row["error"]), 1e-6) for row in chosen], "o-",
                               label=element)
            axes[0].set_xlabel("degrees of freedom")
            axes[0].set_ylabel("|tip deflection error|")
            axes[0].set_title("cantilever vs Timoshenko: element, mesh")
            axes[0].legend(fontsize=8)
        if "fe_mass_mesh" in knobs:
            rows = knobs["fe_mass_mesh"]["rows"]
            for element in ("P1", "P2"):
                for mass in ("lumped", "consistent"):
                    chosen = [row for row in rows if row["element"] == element and row["mass"] == mass]
                    axes[1].loglog([row["seconds_per_period"] for row in chosen],
                                   [max(abs(row["error"]), 1e-6) for row in chosen], "o-", label=f"{element} {mass}")
            axes[1].set_xlabel("wall seconds per simulated period")
            axes[1].set_ylabel("|first frequency error|")
            axes[1].set_title("bar vs pi c / 2L: mass, element, mesh")
            axes[1].legend(fontsize=8)
        save(figure, "fem")

    panels = [name for name in ("fem_every", "verlet_skin", "identity", "ranks")
              if name in knobs or (name == "identity" and "verlet_skin" in knobs)]
    if panels:
        figure, axes = plt.subplots(1, len(panels), figsize=(3.6 * len(panels), 3.4), squeeze=False)
        for axis, name in zip(axes[0], panels):
            if name == "fem_every":
                rows = knobs[name]["rows"]
                base = rows[0]["seconds_per_step"]
                for key in ("rebound", "peak_force", "indentation"):
                    axis.semilogy([row["seconds_per_step"] / base for row in rows[1:]],
                                  [max(abs(row[f"{key}_error"]), 1e-6) for row in rows[1:]], "o-", label=key.replace("_", " "))
                for row in rows[1:]:
                    axis.annotate(f"k={row['fem_every']}", (row["seconds_per_step"] / base, abs(row["rebound_error"])),
                                  fontsize=7)
                axis.set_xlabel("cost per DEM step / fem_every 1")
                axis.set_ylabel("|error vs fem_every 1|")
                axis.set_title("coupling: fem_every")
                axis.legend(fontsize=7)
            elif name == "verlet_skin":
                rows = knobs[name]["rows"]
                skins = [row["skin_radii"] for row in rows]
                base = [row for row in rows if row["skin_radii"] == 0.3][0]["cpu_seconds_per_step"]
                axis.plot(skins, [row["cpu_seconds_per_step"] / base for row in rows], "o-", label="CPU per step / skin 0.3 r")
                axis.set_xlabel("skin [radii]")
                axis.set_ylabel("relative cost")
                axis.set_title("Verlet skin: cost")
                twin = axis.twinx()
                twin.plot(skins, [row["rebuilds"] for row in rows], "s--", color="C1")
                twin.set_ylabel("list rebuilds (dashed)", color="C1")
                axis.legend(fontsize=7, loc="upper center")
            elif name == "identity":
                section = knobs["verlet_skin"]
                growth = section["one_ulp_difference_growth"]
                axis.semilogy([int(step) for step in growth], [max(value, 1e-17) for value in growth.values()], "k-", lw=3,
                              alpha=0.4, label="1 ulp moved (skin 0.3 r)")
                for row in section["rows"]:
                    if row["skin_radii"] != 0.3:
                        growth = row["position_difference_growth"]
                        axis.semilogy([int(step) for step in growth], [max(v, 1e-17) for v in growth.values()], ".-",
                                      label=f"skin {row['skin_radii']} r")
                for row in knobs.get("ranks", {}).get("rows", [])[1:]:
                    growth = row["position_difference_growth"]
                    axis.semilogy([int(step) for step in growth], [max(v, 1e-17) for v in growth.values()], "x--",
                                  label=f"{row['ranks']} ranks vs 1")
                axis.set_xlabel("step")
                axis.set_ylabel("max position difference [radii]")
                axis.set_title("skin, ranks: round-off only")
                axis.legend(fontsize=6)
            else:
                rows = knobs[name]["rows"]
                axis.bar([str(row["ranks"]) for row in rows], [row["seconds_per_step"] * 1e3 for row in rows])
                axis.set_xlabel("MPI ranks")
                axis.set_ylabel("wall ms per step")
                axis.set_title("ranks: cost (shared 2 cores)")
        save(figure, "cost")
    return written


# ============================================================================= summary
def summary(results: dict) -> list:
    """One row per knob setting: (knob, setting, error measure, error, relative cost); cost 1 = the reference."""
    rows, knobs = [], results["knobs"]
    if "steps_per_contact" in knobs:
        section = knobs["steps_per_contact"]
        key = [k for k in section["rows"][0] if k.startswith("hertz_mindlin_e") and k.endswith("_error")][0]
        restitution = key.split("_")[2][1:]
        automatic = section["auto_steps_per_contact"][restitution]   # what dt: auto takes: cost 1
        for row in section["rows"]:
            rows.append(("steps per contact", f"N = {row['steps_per_contact']}", f"restitution (e = {restitution}, Hertz)",
                         row[key], row["steps_per_contact"] / automatic))
    if "contact_model" in knobs:
        section = knobs["contact_model"]
        cost = section["bed_cost"]
        for row in section["rows"]:
            rows.append(("contact model", f"linear at {row['speed']} m/s", "duration vs Hertz",
                         row["linear_spring_dashpot_duration_error"],
                         cost["linear"]["cpu_seconds_per_step"] / cost["hertz"]["cpu_seconds_per_step"]))
    if "rolling_friction" in knobs:
        for row in knobs["rolling_friction"]["rows"]:
            rows.append(("rolling resistance", "on" if row["rolling_friction"] else "off", "deceleration",
                         row["deceleration_error"],
                         row["bed_cpu_seconds_per_step"] / knobs["rolling_friction"]["rows"][1]["bed_cpu_seconds_per_step"]))
    if "verlet_skin" in knobs:
        section = knobs["verlet_skin"]
        base = [row for row in section["rows"] if row["skin_radii"] == 0.3][0]["cpu_seconds_per_step"]
        for row in section["rows"]:
            rows.append(("Verlet skin", f"{row['skin_radii']} r", "positions [radii]", row["position_difference_radii"],
                         row["cpu_seconds_per_step"] / base))
    if "fe_element_mesh" in knobs:
        section = knobs["fe_element_mesh"]["rows"]
        base = max(row["solve_seconds"] for row in section)
        for row in section:
            rows.append(("FE element, mesh", f"{row['element']} {'x'.join(map(str, row['cells']))}", "cantilever tip",
                         row["error"], row["solve_seconds"] / base))
    if "fe_mass_mesh" in knobs:
        section = knobs["fe_mass_mesh"]["rows"]
        base = [row for row in section if row["element"] == "P1" and row["mass"] == "lumped"][-1]["seconds_per_period"]
        for row in section:
            rows.append(("FE mass, mesh", f"{row['element']} {row['mass']} {row['cells']}", "bar frequency", row["error"],
                         row["seconds_per_period"] / base))
    if "fem_every" in knobs:
        section = knobs["fem_every"]["rows"]
        for row in section:
            rows.append(("fem_every", f"k = {row['fem_every']}", "rebound", row["rebound_error"],
                         row["seconds_per_step"] / section[0]["seconds_per_step"]))
    if "ranks" in knobs:
        section = knobs["ranks"]["rows"]
        for row in section:
            rows.append(("ranks", f"{row['ranks']}", "positions [radii]", row["position_difference_radii"],
                         row["seconds_per_step"] / section[0]["seconds_per_step"]))
    return rows


def print_summary(results: dict) -> None:
    print(f"\n{'knob':<20} {'setting':<24} {'error measure':<28} {'error':>11} {'cost':>7}")
    for knob, setting, measure, error, cost in summary(results):
        print(f"{knob:<20} {setting:<24} {measure:<28} {error:>+11.3e} {cost:>7.3g}")
    print("cost: relative to the knob's reference setting (ratios from this run only): CPU time per step for the "
          "granular bed (contact model, rolling, skin), wall time otherwise")


# ============================================================================= markdown (docs/tradeoffs.md)
def _percent(value: float, digits: int = 2) -> str:
    return f"{100 * value:+.{digits}f} %"


def markdown(results: dict) -> str:
    """The tables of docs/tradeoffs.md, from a result file."""
    knobs, out = results["knobs"], []

    def table(header, rows):
        out.append("| " + " | ".join(header) + " |")
        out.append("|" + "---|" * len(header))
        out.extend("| " + " | ".join(str(cell) for cell in row) + " |" for row in rows)
        out.append("")

    if "steps_per_contact" in knobs:
        section = knobs["steps_per_contact"]
        rows = section["rows"]
        restitutions = [key.split("_e")[1].split("_")[0] for key in rows[0]
                        if key.startswith("hertz_mindlin_e") and key.endswith("_error")]
        header = ["N = t_c / dt"] + [f"{model} e = {e}" for e in restitutions for model in ("Hertz", "linear")]
        header += ["Hertz duration (e = 1)", "ms per impact", "cost vs `dt: auto` at e = 0.2"]
        automatic = section["auto_steps_per_contact"][restitutions[0]]
        out.append(f"### steps per contact ({section['touch_phases']} touch phases each; mean, [min, max] for e = 0.2)\n")
        table(header, [[row["steps_per_contact"]]
                       + [(_percent(row[f"{model}_e{e}_error"], 2)
                           + (f" [{_percent(row[f'{model}_e{e}_spread'][0], 1)}, {_percent(row[f'{model}_e{e}_spread'][1], 1)}]"
                              if e == restitutions[0] else ""))
                          for e in restitutions for model in ("hertz_mindlin", "linear_spring_dashpot")]
                       + [_percent(row["hertz_duration_error"], 3), f"{row['seconds_per_contact'] * 1e3:.2f}",
                          f"{row['steps_per_contact'] / automatic:.2f}"] for row in rows])
    if "contact_model" in knobs:
        section = knobs["contact_model"]
        cost = section["bed_cost"]
        out.append("### contact model (elastic impacts, 200 steps per contact; linear k_n derived at 1 m/s)\n")
        table(["impact speed", "Hertz duration", "linear duration", "Hertz peak force", "linear peak force"],
              [[f"{row['speed']} m/s", _percent(row["hertz_mindlin_duration_error"], 2),
                _percent(row["linear_spring_dashpot_duration_error"], 1), _percent(row["hertz_mindlin_peak_force_error"], 2),
                _percent(row["linear_spring_dashpot_peak_force_error"], 1)] for row in section["rows"]])
        base = cost["hertz"]["cpu_seconds_per_step"]
        table(["bed, CPU per step", "Hertz", "linear (k_n derived)", "linear (k_n given)", "Hertz + rolling resistance"],
              [[f"{results['settings']['bed_particles']} spheres"]
               + [f"{cost[name]['cpu_seconds_per_step'] * 1e3:.2f} ms ({cost[name]['cpu_seconds_per_step'] / base:.2f}x)"
                  for name in ("hertz", "linear", "linear_given_stiffness", "rolling_on") if name in cost]])
    if "rolling_friction" in knobs:
        section = knobs["rolling_friction"]
        out.append(f"### rolling resistance ({section['reference']})\n")
        table(["rolling torque", "deceleration [m/s^2]", "error", "distance rolled (first half of the stop)"],
              [["on" if row["rolling_friction"] else "off", f"{row['deceleration']:.4f}",
                _percent(row["deceleration_error"], 2), _percent(row["distance_error"], 2)] for row in section["rows"]])
    if "verlet_skin" in knobs:
        section = knobs["verlet_skin"]
        steps = list(section["one_ulp_difference_growth"])
        base = [row for row in section["rows"] if row["skin_radii"] == 0.3][0]["cpu_seconds_per_step"]
        out.append(f"### Verlet skin ({section['particles']} spheres; max position difference from skin 0.3 r, in radii, "
                   "at steps " + ", ".join(steps) + ")\n")
        rows = [["1 ulp moved (yardstick)", "", "", "", "", " / ".join(f"{v:.0e}" for v in section["one_ulp_difference_growth"].values())]]
        for row in section["rows"]:
            rows.append([f"{row['skin_radii']} r", f"{row['cpu_seconds_per_step'] * 1e3:.2f} ms ({row['cpu_seconds_per_step'] / base:.2f}x)",
                         row["rebuilds"], row["listed_pairs"], row["contacts"],
                         " / ".join(f"{v:.0e}" for v in row["position_difference_growth"].values())])
        table(["skin", "CPU per step", f"rebuilds in {section['steps']} steps", "listed pairs", "contacts",
               "position difference"], rows)
    if "fe_element_mesh" in knobs:
        out.append(f"### element and mesh: cantilever ({knobs['fe_element_mesh']['reference']})\n")
        table(["element", "hexahedra", "DOF", "tip deflection error", "static solve [s]"],
              [[row["element"], "×".join(map(str, row["cells"])), row["dofs"], _percent(row["error"], 3),
                f"{row['solve_seconds']:.3f}"] for row in knobs["fe_element_mesh"]["rows"]])
    if "fe_mass_mesh" in knobs:
        rows = knobs["fe_mass_mesh"]["rows"]
        base = [row for row in rows if row["element"] == "P1" and row["mass"] == "lumped"][0]["seconds_per_period"]
        out.append(f"### mass, element and mesh: bar frequency ({knobs['fe_mass_mesh']['reference']})\n")
        table(["element", "mass", "cells", "DOF", "frequency error", "steps per period", "ms per period",
               "cost vs P1 lumped 4"],
              [[row["element"], row["mass"], row["cells"], row["dofs"], _percent(row["error"], 4),
                f"{row['steps_per_period']:.0f}", f"{row['seconds_per_period'] * 1e3:.1f}",
                f"{row['seconds_per_period'] / base:.1f}x"] for row in rows])
    if "fem_every" in knobs:
        section = knobs["fem_every"]
        rows = section["rows"]
        out.append(f"### fem_every (ball on a soft block, P1 {'×'.join(map(str, section['cells']))}; reference fem_every = 1)\n")
        table(["fem_every", "rebound", "peak force", "block indentation", "FE sub-steps per advance", "ms per DEM step",
               "cost vs 1"],
              [[row["fem_every"] if row["effective_fem_every"] == row["fem_every"]
                else f"{row['fem_every']} (run: {row['effective_fem_every']})",
                _percent(row["rebound_error"], 2), _percent(row["peak_force_error"], 2),
                _percent(row["indentation_error"], 2), row["fem_substeps"], f"{row['seconds_per_step'] * 1e3:.3f}",
                f"{row['seconds_per_step'] / rows[0]['seconds_per_step']:.2f}x"] for row in rows])
    if "ranks" in knobs:
        section = knobs["ranks"]
        out.append(f"### ranks ({section['particles']} spheres; max position difference from 1 rank, in radii)\n")
        table(["ranks", "wall ms per step", "speed-up", "position difference"],
              [[row["ranks"], f"{row['seconds_per_step'] * 1e3:.2f}", f"{row['speedup']:.2f}",
                " / ".join(f"{v:.0e}" for v in row["position_difference_growth"].values())] for row in section["rows"]])
    machine = results["machine"]
    out.append(f"Measured {machine['when']}, {machine['cores']} cores, load average "
               f"{' / '.join(f'{value:.1f}' for value in machine['load_average'] or [])} at the start, "
               f"{results['total_seconds']:.0f} s in all.")
    return "\n".join(out)


# ============================================================================= driver
def machine() -> dict:
    try:
        load = os.getloadavg()
    except OSError:
        load = None
    return {"processor": platform.processor() or platform.machine(), "cores": os.cpu_count(), "load_average": load,
            "python": platform.python_version(), "when": time.strftime("%Y-%m-%d %H:%M:%S UTC", time.gmtime())}


def warm_up() -> None:
    """Compile (or load from the cache) every kernel the timed sections use, untimed: one tiny run of each."""
    impact("hertz_mindlin", 0.5, IMPACT_SPEED, 10, 0.5)
    impact("linear_spring_dashpot", 0.5, IMPACT_SPEED, 10, 0.5)
    for keys in ({}, {"model": "linear_spring_dashpot"}, {"rolling_friction": 0.05}):
        run_bed(bed_scene(27, **keys), 2, 2)
    bar_frequency("P1", "lumped", 2, periods=1.0)
    bar_frequency("P2", "consistent", 2, periods=1.0)
    with tempfile.TemporaryDirectory(prefix="tradeoffs-warm-") as scratch:
        Simulation.from_dict(ball_on_block(height=0.701, speed=2.4, block_modulus=1e8), output_dir=scratch).step(3)


def run(settings: dict, only, log=print) -> dict:
    results = {"machine": machine(), "settings": {key: value for key, value in settings.items()}, "knobs": {}}
    wanted = list(only or KNOBS)
    log("warming up (kernels compiled or loaded, untimed)")
    warm_up()
    costs = None
    if "contact_model" in wanted or "rolling_friction" in wanted:
        log("granular bed: cost per step of the contact model and of rolling resistance")
        costs = bed_costs(settings, log)
    sections = {
        "steps_per_contact": lambda: knob_steps_per_contact(settings, log),
        "contact_model": lambda: knob_contact_model(settings, costs, log),
        "rolling_friction": lambda: knob_rolling_friction(settings, costs, log),
        "verlet_skin": lambda: knob_verlet_skin(settings, log),
        "fe_element_mesh": lambda: knob_fe_element_mesh(settings, log),
        "fe_mass_mesh": lambda: knob_fe_mass_mesh(settings, log),
        "fem_every": lambda: knob_fem_every(settings, log),
        "ranks": lambda: knob_ranks(settings, log),
    }
    for name in wanted:
        log(f"{name}:")
        started = time.perf_counter()
        results["knobs"][name] = sections[name]()
        results["knobs"][name]["benchmark_seconds"] = time.perf_counter() - started
    return results


def parse_arguments(argv=None):
    parser = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    parser.add_argument("--quick", action="store_true", help="fewer cases and steps")
    parser.add_argument("--only", nargs="+", choices=KNOBS, help="run these knobs only")
    parser.add_argument("--json", type=Path, default=DEFAULT_JSON)
    parser.add_argument("--plots", type=Path, default=DEFAULT_PLOTS, help="folder for tradeoffs_*.png")
    parser.add_argument("--no-plots", action="store_true")
    parser.add_argument("--markdown", type=Path, nargs="?", const=True, default=None,
                        help="print the tables of docs/tradeoffs.md; with a JSON path, from that file without running")
    return parser.parse_args(argv)


def main(argv=None) -> int:
    argv = sys.argv[1:] if argv is None else argv
    if argv and argv[0] == WORKER_FLAG:
        ranks_worker(argv[1], int(argv[2]), int(argv[3]), int(argv[4]), [int(mark) for mark in argv[5].split(",") if mark])
        return 0
    args = parse_arguments(argv)
    if isinstance(args.markdown, Path):
        print(markdown(json.loads(args.markdown.read_text())))
        return 0
    settings = QUICK if args.quick else FULL
    started = time.perf_counter()
    results = run(settings, args.only)
    results["quick"] = args.quick
    results["total_seconds"] = time.perf_counter() - started
    print_summary(results)
    args.json.parent.mkdir(parents=True, exist_ok=True)
    args.json.write_text(json.dumps(results, indent=1, default=float))
    print(f"wrote {args.json} ({results['total_seconds']:.0f} s)")
    if not args.no_plots:
        for path in draw(results, args.plots):
            print(f"wrote {path}")
    if args.markdown:
        print(markdown(results))
    return 0


if __name__ == "__main__":
    raise SystemExit(main())

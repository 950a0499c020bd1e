"""Strong and weak scaling of the MPI-parallel DEM on the settle scene (docs/parallel.md).

    python benchmarks/scaling.py --mode strong --particles 200000 --ranks 1 2
    python benchmarks/scaling.py --mode weak --per-rank 50000 --ranks 1 2 4
    python benchmarks/scaling.py --mode both --particles 20000 --per-rank 10000 --ranks 1 2 --steps 200
    python benchmarks/scaling.py --mode fem --columns 40 --rows 20 --layers 2 --ranks 1 2 --steps 200
    python benchmarks/scaling.py --mode coupled --columns 16 --rows 8 --layers 1 --particles 4000 --ranks 1 2

Modes strong / weak / both time the DEM; fem times an FE plate alone and coupled the whole coupled
step (benchmarks/scaling_solids.py: the scenes), each strong (--study strong: fixed size) or weak
(--study weak: --columns and --per-rank per rank).

The scene is benchmarks/settle.py's (glass spheres d = 2 mm, E = 5 MPa, mu = 0.5, e = 0.5,
dt = 2e-5 s, skin 0.3 r, settling in a five-wall box) on a compact lattice (spacing 2.04 mm,
see scene_dict; --spacing 2.4e-3 gives settle.py's own lattice) so that the timed steps have
contacts; strong scaling keeps the particle count fixed, weak scaling grows it with the rank
count (the footprint grows, the fill height stays).  For every rank count
the driver launches this file under mpiexec (pdemfem.launch); each run compiles on a tiny
copy, builds the scene, takes --pre-steps untimed steps and times --steps steps.

Figures per run:
  particle-steps/s      particles * steps / wall seconds of the timed steps
  efficiency            strong: T(1) / (p T(p)); weak: T(1) / T(p) (throughput per rank vs 1 rank)
  communication share   time in the ghost update (GhostExchange.start_update + finish_update) + migrate + the
                        MPI reductions of the step (allreduce/Allreduce/Allgather, including the waiting in
                        them for slower ranks) over the timed wall time, max over ranks; measured by wrapping those
                        calls in this benchmark only (no timers in the solver)
  imbalance             max/mean over ranks of owned particles, and of the time outside
                        communication (compute), at the end
  collectives/step      the particle system's collective calls (those timed above) per timed step, rank 0,
                        rebuild steps included (a step without a rebuild makes 2: one MAX, one SUM)
  lost s run/drift/step the time lost to waiting, sum over steps of (slowest rank's work - mean), split by
                        timescale: the whole run's imbalance, its drift over blocks of 100 steps (load
                        moving between rebalances), and step-to-step changes with the machine's jitter
                        (waiting_by_timescale)
  efficiency vs busy    strong, --busy-reference: T_busy(1) / (p T(p)), T_busy(1) the fastest one-rank run made
                        while p-1 copies of it run beside it (each pinned to its own core, and the lone
                        one-rank runs to core 0, when this machine's cores 0 .. p-1 are ours): what a core
                        does when every core works, so what is left is the parallel code's own loss (ghosts,
                        waiting, migration), not the machine's shared caches, memory bandwidth and clock;
                        printed also from the medians of the runs (plain and against the busy reference),
                        which one fast or slow spell moves less
  work                  the ranks' time outside the timed communication, summed (core-seconds), against the
                        one-rank run's: what running on p ranks adds to the work itself (pairs across a cut
                        computed on both sides, ghost rows in the list, the rebuild's partitioning, cores
                        sharing caches and memory), apart from waiting and messages
  rounds                --repeat N: each round's p-rank run against the same round's one-rank run (taken back
                        to back), per round and their median: the host's drift over the study moves these
                        less than the fastest runs, which can come from different rounds
  block floor           --repeat N: the sum over blocks of 100 timed steps of each block's fastest run, and
                        the efficiency from it.  Runs of one rank count compute the same steps bit for bit
                        (checked by their final positions), so block k is the same work in each run and what
                        a run adds to its fastest time there is the machine's; the fastest whole run needs
                        all blocks quiet at once, the floor each block quiet in one run
  machine               (several ranks, default launcher) the cores' capacity before each round: how many
                        cores' speed a register loop gets on p cores at once (benchmarks/core_capacity.py);
                        p on dedicated cores, less where the virtual cores share the host's time
--rebalance-threshold X sets the scene's parallel.rebalance_threshold (default 1.2).
--repeat N runs each rank count N times, the rank counts in turn, and keeps the fastest run of each (the
machine's speed drifts by tens of per cent within minutes; the wall times of all runs are printed too).
JSON and a PNG go to benchmarks/results/scaling.{json,png} (or --json PATH).
"""
from __future__ import annotations

import argparse
import json
import os
import platform
import shlex
import subprocess
import sys
import tempfile
import time
from pathlib import Path

HERE = Path(__file__).resolve().parent
REPOSITORY = HERE.parent
sys.path.insert(0, str(HERE))
import settle  # noqa: E402  (the settle benchmark's materials, walls and step)
from core_capacity import core_capacity  # noqa: E402  (how much of p cores the machine gives at once)

import numpy as np  # noqa: E402

DEFAULT_JSON = HERE / "results" / "scaling.json"
WORKER_FLAG = "--worker-json"
CAPACITY_ROUNDS = 6  # register-loop rounds of the core-capacity probe before each round of runs (~0.7 s)
COMPACT_SPACING = 2.04e-3   # lattice spacing: gaps of 0.04 mm, below the 0.3 mm skin


def scene_dict(particles: int, spacing: float = COMPACT_SPACING) -> dict:
    """benchmarks/settle.py's scene on a compact lattice: every particle has listed neighbours from
    the first step and the bed compacts under gravity while it is timed (settle.py's 2.4 mm
    lattice spends its first ~1000 steps in free fall with an empty neighbour list).  The
    footprint grows as sqrt(particles) (25 x 25 sites at 28,000 particles), the height follows."""
    import math

    sites = max(1, round(settle.REFERENCE_SITES_PER_SIDE * math.sqrt(particles / settle.REFERENCE_PARTICLES)))
    layers = math.ceil(particles / (sites * sites))
    side = sites * spacing
    height = (layers + 2) * spacing
    scene = settle.scene_dict(particles)
    low = (spacing - settle.DIAMETER) / 2
    scene["particles"][0]["insert"].update({"region": {"box": [[low, low, low], [side, side, height]]},
                                            "spacing": spacing})
    for wall in scene["walls"]:
        for axis, name in ((0, "x_high"), (1, "y_high")):
            if wall["name"] == name:
                wall["point"][axis] = side
    return scene
TIMED_COLLECTIVES = ("allreduce", "Allreduce", "Iallreduce", "Allgather", "allgather", "Alltoall", "Alltoallv",
                     "Barrier")


class _CommTimer:
    """Accumulates wall time per label; a nested timed call inside a timed call is not counted twice."""

    def __init__(self):
        self.seconds = {}
        self.calls = {}
        self._depth = 0

    def timed(self, label, function):
        def wrapper(*args, **kwargs):
            if self._depth:
                return function(*args, **kwargs)
            self._depth += 1
            start = time.perf_counter()
            try:
                return function(*args, **kwargs)
            finally:
                self._depth -= 1
                self.seconds[label] = self.seconds.get(label, 0.0) + time.perf_counter() - start
                self.calls[label] = self.calls.get(label, 0) + 1
        return wrapper

    def reset(self):
        self.seconds.clear()
        self.calls.clear()


class _TimedComm:
    """A communicator proxy whose collectives are timed (everything else is delegated)."""

    def __init__(self, comm, timer):
        self._comm = comm
        for name in TIMED_COLLECTIVES:
            setattr(self, name, timer.timed("reductions", getattr(comm, name)))

    def __getattr__(self, name):
        return getattr(self._comm, name)


def instrument(sim, timer):
    """Wrap ghost update, migration, rebuild and the particle system's collectives."""
    import pdemfem.parallel.exchange as exchange_module
    import pdemfem.particles.system as system_module

    system = sim.particle_system
    system_module.migrate = timer.timed("migration", exchange_module.migrate)
    # The step posts the update (start_update) and takes it in (finish_update) around the pairs of two owned
    # particles: both halves count as ghost update, the pairs between them do not.
    for half in ("start_update", "finish_update"):
        setattr(exchange_module.GhostExchange, half,
                timer.timed("ghost update", getattr(exchange_module.GhostExchange, half)))
    # The rebuild as a whole (sort, migration, ghost planning, list) is reported separately;
    # its communication parts are counted under their own labels, so it is timed beside them.
    original_rebuild = system._rebuild

    def rebuild(*args, **kwargs):
        start = time.perf_counter()
        try:
            return original_rebuild(*args, **kwargs)
        finally:
            timer.rebuild_seconds = getattr(timer, "rebuild_seconds", 0.0) + time.perf_counter() - start
            timer.rebuilds = getattr(timer, "rebuilds", 0) + 1
    system._rebuild = rebuild
    system.comm = _TimedComm(system.comm, timer)
    # A SUM left in flight (ParticleSystem.defer_step_sum) is waited for in finish_sum: that wait is reduction time.
    system.reductions.finish_sum = timer.timed("reductions wait", system.reductions.finish_sum)
    if system.ghosts is not None:
        system.ghosts.comm = system.comm


def record_step_work(system, timer, steps: int):
    """Each step's time outside communication on this rank (wall time of ParticleSystem.step minus the timed
    communication in it), and the clock at each step's start, filled in as the timed steps run."""
    work = np.zeros(steps)
    starts = np.zeros(steps)
    original_step = system.step
    progress = {"step": 0}

    def step():
        communication_before = sum(timer.seconds.values())
        start = time.perf_counter()
        original_step()
        elapsed = time.perf_counter() - start
        index = progress["step"]
        if index < steps:
            work[index] = elapsed - (sum(timer.seconds.values()) - communication_before)
            starts[index] = start
        progress["step"] = index + 1
    system.step = step
    return work, starts


WAITING_BLOCK_STEPS = 100


def block_seconds(starts, end: float) -> list:
    """Wall seconds of each block of WAITING_BLOCK_STEPS timed steps (the last block may be shorter), from
    the clock at each step's start and at the end of the timed steps: whatever runs between the steps
    (the run loop, the monitor) is counted in its block."""
    boundaries = list(starts[::WAITING_BLOCK_STEPS]) + [end]
    return [float(later - earlier) for earlier, later in zip(boundaries[:-1], boundaries[1:])]


def floor_seconds(block_runs) -> float:
    """The block floor: the sum over blocks of the fastest run's time for that block.  Runs of one rank
    count compute the same steps bit for bit, so block k is the same work in every run, and the time a run
    adds to it is the machine's (another process on the core, a slow spell of the host).  The fastest of N
    whole runs needs every block quiet at once; this needs each block quiet in one of the N runs."""
    return float(np.sum(np.min(np.array(block_runs), axis=0)))


def waiting_by_timescale(work) -> dict:
    """Where the ranks' waiting comes from, from each rank's work per step (ranks x steps).  Every step ends
    in a reduction, so a step lasts as long as its slowest rank's work: the time lost to waiting is
    sum over steps of (max - mean over ranks).  Split by timescale:
      run    max - mean of the ranks' whole-run work: what the partition's balance itself leaves;
      drift  the same over blocks of WAITING_BLOCK_STEPS steps, less `run`: load moving between rebalances;
      step   the rest: step-to-step changes (rebuild steps load the ranks differently from plain steps)
             and the machine's jitter."""
    if work.shape[0] < 2 or work.shape[1] == 0:
        return {"run": 0.0, "drift": 0.0, "step": 0.0}
    per_step = float(np.sum(work.max(axis=0) - work.mean(axis=0)))
    blocks = np.add.reduceat(work, np.arange(0, work.shape[1], WAITING_BLOCK_STEPS), axis=1)
    per_block = float(np.sum(blocks.max(axis=0) - blocks.mean(axis=0)))
    totals = work.sum(axis=1)
    whole = float(totals.max() - totals.mean())
    return {"run": whole, "drift": per_block - whole, "step": per_step - per_block}


def worker(args) -> dict:
    from mpi4py import MPI

    from pdemfem import Simulation

    comm = MPI.COMM_WORLD
    ranks = comm.size
    if args.core is not None:  # --busy-reference's one-rank runs: each on its own core, the lone one too
        os.sched_setaffinity(0, {args.core})
    with tempfile.TemporaryDirectory(prefix="scaling-bench-") as scratch:
        tiny = Simulation.from_dict(scene_dict(27 * ranks), comm=comm, output_dir=os.path.join(scratch, "tiny"))
        tiny.step(3)
        del tiny
        build_start = time.perf_counter()
        scene = scene_dict(args.particles, args.spacing)
        if args.rebalance_threshold is not None:
            scene["parallel"] = {"rebalance_threshold": args.rebalance_threshold}
        sim = Simulation.from_dict(scene, comm=comm, output_dir=os.path.join(scratch, "out"))
        build_seconds = comm.allreduce(time.perf_counter() - build_start, op=MPI.MAX)
        particles = sim.particle_count()
        sim.step(args.pre_steps)
        timer = _CommTimer()
        instrument(sim, timer)
        step_work, step_starts = record_step_work(sim.particle_system, timer, args.steps)
        comm.Barrier()
        timer.reset()
        timer.rebuild_seconds, timer.rebuilds = 0.0, 0
        start = time.perf_counter()
        sim.step(args.steps)
        end = time.perf_counter()
        elapsed = end - start
        comm.Barrier()  # not timed: the step's own reductions already synchronise the ranks
        system = sim.particle_system
        local = {
            "comm": sum(timer.seconds.values()),
            "ghost": timer.seconds.get("ghost update", 0.0),
            "migration": timer.seconds.get("migration", 0.0),
            "reductions": timer.seconds.get("reductions", 0.0) + timer.seconds.get("reductions wait", 0.0),
            "rebuild": timer.rebuild_seconds,
            "collective_calls": float(timer.calls.get("reductions", 0)),
            "owned": float(system.state.owned_count),
            "ghosts": float(system.state.ghost_count),
            "elapsed": elapsed,
        }
        contacts = sim.contact_count()
        # Identifies the trajectory: equal in every run of one rank count when the runs compute the same
        # steps (the block floor's premise); the same reduction order on every run of that rank count.
        checksum = comm.allreduce(float(np.sum(system.state.positions[:system.state.owned_count])))
        rebuilds = timer.rebuilds
        rebalances = system.rebalances
    gathered = comm.gather(local, root=0)
    work = comm.gather(step_work, root=0)
    if comm.rank != 0:
        return {}
    wall = max(item["elapsed"] for item in gathered)
    compute = np.array([item["elapsed"] - item["comm"] for item in gathered])
    owned = np.array([item["owned"] for item in gathered])
    return {
        "ranks": ranks,
        "particles": particles,
        "steps": args.steps,
        "pre_steps": args.pre_steps,
        "wall_seconds": wall,
        "particle_steps_per_second": particles * args.steps / wall,
        "communication_share": max(item["comm"] for item in gathered) / wall,
        "communication_seconds_by_part_max": {key: max(item[key] for item in gathered)
                                              for key in ("ghost", "migration", "reductions")},
        "rebuild_seconds_max": max(item["rebuild"] for item in gathered),
        "rebuilds": rebuilds,
        "rebalances": rebalances,
        "collectives_per_step": gathered[0]["collective_calls"] / max(args.steps, 1),
        "imbalance_particles": float(owned.max() / owned.mean()),
        "imbalance_compute": float(compute.max() / compute.mean()),
        "ghosts_per_owned": float(sum(item["ghosts"] for item in gathered) / owned.sum()),
        "contacts_at_end": contacts,
        "build_seconds": build_seconds,
        "waiting_by_timescale": waiting_by_timescale(np.array(work)),
        # Rank 0's clock: every step ends in a reduction over the ranks, so the ranks' blocks agree.
        "block_wall_seconds": block_seconds(step_starts, end),
        # The ranks' time outside the timed communication, summed: against the one-rank run's, what running
        # on several ranks adds to the work itself (pairs across the cuts on both ranks, ghost rows in the list,
        # the rebuild's partitioning, the cores sharing caches and memory).
        "work_core_seconds": float(np.sum(work)),
        "positions_checksum": checksum,
    }


def launch_solids(ranks: int, args) -> dict:
    with tempfile.TemporaryDirectory(prefix="scaling-run-") as scratch:
        part = os.path.join(scratch, "run.json")
        prefix = ([*shlex.split(args.launcher), "-n", str(ranks)] if args.launcher
                  else [sys.executable, "-m", "pdemfem.launch", "-n", str(ranks), "--"])
        command = [*prefix, sys.executable, str(Path(__file__).resolve()), WORKER_FLAG, part, "--mode", args.mode,
                   "--study", args.study, "--columns", str(args.columns), "--rows", str(args.rows),
                   "--layers", str(args.layers), "--particles", str(args.particles), "--per-rank",
                   str(args.per_rank), "--steps", str(args.steps), "--pre-steps", str(args.pre_steps)]
        subprocess.run(command, check=True, cwd=REPOSITORY)
        with open(part) as handle:
            return json.load(handle)


def solids_study(args) -> list:
    rows = []
    for ranks in args.ranks:
        print(f"[{args.mode}, {args.study}] {ranks} rank(s) ...", flush=True)
        rows.append(launch_solids(ranks, args))
    base = rows[0]["wall_seconds"] / rows[0]["steps"]
    for row in rows:
        per_step = row["wall_seconds"] / row["steps"]
        # strong: T(1) / (p T(p)); weak: T(1) / T(p).
        row["efficiency"] = base / (row["ranks"] * per_step) if args.study == "strong" else base / per_step
    print(f"\n{args.mode} {args.study} scaling ({rows[0]['steps']} timed steps after {rows[0]['pre_steps']})")
    print(f"{'ranks':>5} {'nodes':>8} {'particles':>9} {'FE sub/step':>11} {'ms/step':>9} {'node-steps/s':>13} "
          f"{'effic.':>7}")
    for row in rows:
        print(f"{row['ranks']:>5} {row['nodes']:>8} {row['particles']:>9} {row['fem_substeps_per_step']:>11} "
              f"{1e3 * row['wall_seconds'] / row['steps']:>9.3f} {row['node_steps_per_second']:>13.3g} "
              f"{100 * row['efficiency']:>6.1f}%")
    return rows


def _command(ranks: int, particles: int, args, part: str, core=None) -> list:
    if args.launcher:  # e.g. "srun --cpu-bind=cores" on a cluster (jobs/)
        prefix = [*shlex.split(args.launcher), "-n", str(ranks)]
    else:
        prefix = [sys.executable, "-m", "pdemfem.launch", "-n", str(ranks), "--"]
    command = [*prefix, sys.executable, str(Path(__file__).resolve()), WORKER_FLAG, part,
               "--particles", str(particles), "--steps", str(args.steps), "--pre-steps", str(args.pre_steps),
               "--spacing", repr(args.spacing)]
    if args.rebalance_threshold is not None:
        command += ["--rebalance-threshold", repr(args.rebalance_threshold)]
    if core is not None:
        command += ["--core", str(core)]
    return command


def launch(ranks: int, particles: int, args) -> dict:
    with tempfile.TemporaryDirectory(prefix="scaling-run-") as scratch:
        part = os.path.join(scratch, "run.json")
        # With --busy-reference the lone one-rank run is pinned like the side-by-side copies (to core 0), so
        # that the two differ only in the other cores' load.
        core = 0 if args.busy_reference and ranks == 1 and _can_pin(1, args) else None
        subprocess.run(_command(ranks, particles, args, part, core), check=True, cwd=REPOSITORY)
        with open(part) as handle:
            return json.load(handle)


def _can_pin(cores: int, args) -> bool:
    """Whether one-rank runs can be pinned to cores 0 .. cores-1: the default launcher (a cluster's launcher
    binds by its own rules) and those cores ours."""
    return not args.launcher and hasattr(os, "sched_getaffinity") and set(range(cores)) <= os.sched_getaffinity(0)


def launch_side_by_side(copies: int, particles: int, args) -> list:
    """`copies` one-rank runs of the same case at once, pinned to cores 0 .. copies-1 where this process may
    use them: the one-rank reference with the machine as busy as a `copies`-rank run keeps it (shared caches,
    memory bandwidth, clock)."""
    with tempfile.TemporaryDirectory(prefix="scaling-busy-") as scratch:
        parts = [os.path.join(scratch, f"run{copy}.json") for copy in range(copies)]
        pin = _can_pin(copies, args)
        processes = [subprocess.Popen(_command(1, particles, args, part, copy if pin else None), cwd=REPOSITORY)
                     for copy, part in enumerate(parts)]
        if any(process.wait() != 0 for process in processes):
            raise RuntimeError("a side-by-side one-rank run failed (its output is above)")
        rows = []
        for part in parts:
            with open(part) as handle:
                rows.append(json.load(handle))
        return rows


def study(mode: str, args) -> list:
    """One row per rank count: the fastest of --repeat runs, the rank counts taken in turn in each round (on a
    shared machine the speed drifts by tens of per cent within minutes: one run of each would compare
    different machines; the fastest run is the closest to an undisturbed one)."""
    best = {}
    runs = {ranks: [] for ranks in args.ranks}
    blocks = {ranks: [] for ranks in args.ranks}
    checksums = {ranks: set() for ranks in args.ranks}
    busy = []  # --busy-reference: wall seconds of the one-rank runs made side by side
    busy_work = []  # and their work (core-seconds outside the timed communication)
    capacities = []  # the machine's core capacity (core_capacity.py) before each round
    for round_index in range(args.repeat):
        if max(args.ranks) > 1 and not args.launcher:
            capacities.append(core_capacity(max(args.ranks), rounds=CAPACITY_ROUNDS)["capacity"])
        for ranks in args.ranks:
            particles = args.particles if mode == "strong" else args.per_rank * ranks
            print(f"[{mode}] {ranks} rank(s), {particles} particles, run {round_index + 1}/{args.repeat} ...",
                  flush=True)
            row = launch(ranks, particles, args)
            runs[ranks].append(row["wall_seconds"])
            blocks[ranks].append(row["block_wall_seconds"])
            checksums[ranks].add(row["positions_checksum"])
            if ranks not in best or row["wall_seconds"] < best[ranks]["wall_seconds"]:
                best[ranks] = row
        if args.busy_reference and mode == "strong":
            copies = max(args.ranks)
            print(f"[{mode}] {copies} one-rank runs side by side, {args.particles} particles, "
                  f"run {round_index + 1}/{args.repeat} ...", flush=True)
            for row in launch_side_by_side(copies, args.particles, args):
                busy.append(row["wall_seconds"])
                busy_work.append(row["work_core_seconds"])
    rows = [best[ranks] for ranks in args.ranks]
    for row in rows:
        row["wall_seconds_of_runs"] = runs[row["ranks"]]
        # Only when every run of the rank count computed the same trajectory (same final positions, bit
        # for bit) is block k the same work in every run.
        if args.repeat > 1 and len(checksums[row["ranks"]]) == 1:
            row["block_wall_seconds_of_runs"] = blocks[row["ranks"]]
            row["block_floor_wall_seconds"] = floor_seconds(blocks[row["ranks"]])
    base = rows[0]
    for row in rows:
        if capacities:
            row["core_capacity_of_rounds"] = capacities
        base_per_rank = base["particle_steps_per_second"] / base["ranks"]
        row["efficiency"] = row["particle_steps_per_second"] / row["ranks"] / base_per_rank
        if "block_floor_wall_seconds" in row and "block_floor_wall_seconds" in base:
            # Weak scaling: T(1) / T(p), as the throughput per rank.
            scale = row["particles"] / base["particles"] if mode == "weak" else 1.0
            row["efficiency_of_block_floors"] = (base["block_floor_wall_seconds"] * base["ranks"] * scale
                                                 / (row["ranks"] * row["block_floor_wall_seconds"]))
        if args.repeat > 1 and row is not base:
            # Each round's own runs against each other (taken back to back, minutes apart at most): the host's
            # drift over the study moves these less than it moves the fastest runs, taken in different rounds.
            scale = row["particles"] / base["particles"] if mode == "weak" else 1.0
            row["efficiency_of_rounds"] = [base_wall * base["ranks"] * scale / (row["ranks"] * wall)
                                           for base_wall, wall in zip(runs[base["ranks"]], runs[row["ranks"]])]
        if "work_core_seconds" in row:
            # Per particle, as the efficiency: what the p-rank run adds to the one-rank run's work (0 for it).
            row["work_increase"] = (row["work_core_seconds"] * base["particles"]
                                    / (row["particles"] * base["work_core_seconds"]) - 1.0)
        if busy:
            # The fastest side-by-side one-rank run, as every row is the fastest of its runs; the medians too,
            # which a single fast or slow spell of the machine moves less.
            row["busy_reference_wall_seconds_of_runs"] = busy
            row["busy_reference_work_core_seconds_of_runs"] = busy_work
            row["efficiency_against_busy_reference"] = min(busy) / (row["ranks"] * row["wall_seconds"])
            median_wall = float(np.median(runs[row["ranks"]]))
            row["efficiency_of_medians"] = float(np.median(runs[base["ranks"]])) * base["ranks"] / (
                row["ranks"] * median_wall)
            row["efficiency_against_busy_reference_of_medians"] = float(np.median(busy)) / (row["ranks"] * median_wall)
    if capacities and rows[-1]["ranks"] == max(args.ranks) > 1:
        # What the machine gave p busy cores, p x efficiency / capacity: the efficiency against a p-rank run that
        # got `capacity` cores' speed (the block floor's when there is one, else the fastest runs').
        row = rows[-1]
        efficiency = row.get("efficiency_of_block_floors", row["efficiency"])
        row["efficiency_against_core_capacity"] = efficiency * row["ranks"] / float(np.median(capacities))
    return rows


def print_table(mode: str, rows: list) -> None:
    runs = len(rows[0].get("wall_seconds_of_runs", [None]))
    print(f"\n{mode} scaling ({rows[0]['steps']} timed steps after {rows[0]['pre_steps']}"
          f"{f'; the fastest of {runs} runs per row' if runs > 1 else ''})")
    print(f"{'ranks':>5} {'particles':>10} {'wall s':>8} {'p-steps/s':>11} {'effic.':>7} {'comm %':>7} "
          f"{'ghost/migr/red s':>18} {'rebuild s':>9} {'imb. N':>6} {'imb. t':>6} {'ghost/own':>9} {'coll/step':>9} "
          f"{'lost s run/drift/step':>22}")
    for row in rows:
        parts = row["communication_seconds_by_part_max"]
        waiting = row.get("waiting_by_timescale", {"run": 0.0, "drift": 0.0, "step": 0.0})
        print(f"{row['ranks']:>5} {row['particles']:>10} {row['wall_seconds']:>8.2f} "
              f"{row['particle_steps_per_second']:>11.3g} {100 * row['efficiency']:>6.1f}% "
              f"{100 * row['communication_share']:>6.1f}% "
              f"{parts['ghost']:>5.2f}/{parts['migration']:>5.2f}/{parts['reductions']:>5.2f} "
              f"{row['rebuild_seconds_max']:>9.2f} {row['imbalance_particles']:>6.3f} "
              f"{row['imbalance_compute']:>6.3f} {row['ghosts_per_owned']:>9.3f} "
              f"{row.get('collectives_per_step', 0.0):>9.2f} "
              f"{waiting['run']:>6.2f}/{waiting['drift']:>6.2f}/{waiting['step']:>6.2f}")
    if runs > 1:
        for row in rows:
            seconds = ", ".join(f"{value:.2f}" for value in row["wall_seconds_of_runs"])
            print(f"  {row['ranks']} rank(s), wall s of the runs in order: {seconds}")
    for row in rows:
        if "efficiency_of_rounds" in row:
            values = row["efficiency_of_rounds"]
            print(f"  {row['ranks']} rank(s) against {rows[0]['ranks']} within each round (its runs back to back): "
                  + ", ".join(f"{100 * value:.1f}%" for value in values)
                  + f" (median {100 * float(np.median(values)):.1f}%)")
    if len(rows) > 1 and all("work_increase" in row for row in rows):
        print("  work (time outside the timed communication, summed over the ranks; the fastest run): " + ", ".join(
            f"{row['ranks']} rank(s) {row['work_core_seconds']:.2f} core-s"
            + (f" ({100 * row['work_increase']:+.0f} %)" if row is not rows[0] else "") for row in rows))
    if "efficiency_of_block_floors" in rows[-1]:
        print(f"  block floor (the sum over blocks of {WAITING_BLOCK_STEPS} steps of each block's fastest run; "
              "the runs computed the same steps bit for bit): " + ", ".join(
                  f"{row['ranks']} rank(s) {row['block_floor_wall_seconds']:.2f} s, "
                  f"{100 * row['efficiency_of_block_floors']:.1f}%" for row in rows))
    elif runs > 1:
        print("  no block floor: the runs of a rank count did not end in the same positions")
    if "core_capacity_of_rounds" in rows[-1]:
        capacities = rows[-1]["core_capacity_of_rounds"]
        print(f"  machine: a register loop on {max(row['ranks'] for row in rows)} cores at once got "
              + ", ".join(f"{value:.2f}" for value in capacities)
              + f" cores' speed before the rounds (median {float(np.median(capacities)):.2f}; "
              "benchmarks/core_capacity.py)")
        if "efficiency_against_core_capacity" in rows[-1]:
            print(f"  efficiency against that capacity ({rows[-1]['ranks']} x efficiency / capacity, the block floor's "
                  f"if any): {100 * rows[-1]['efficiency_against_core_capacity']:.1f}%")
    if "efficiency_against_busy_reference" in rows[0]:
        busy = rows[0]["busy_reference_wall_seconds_of_runs"]
        print(f"  busy reference: one-rank runs made {max(row['ranks'] for row in rows)} at a time, wall s: "
              + ", ".join(f"{value:.2f}" for value in busy))
        print("  efficiency against the fastest of them (the machine's shared caches, memory bandwidth and clock "
              "taken out): " + ", ".join(f"{row['ranks']} rank(s) {100 * row['efficiency_against_busy_reference']:.1f}%"
                                         for row in rows))
        print("  the same from the medians of the runs: " + ", ".join(
            f"{row['ranks']} rank(s) {100 * row['efficiency_of_medians']:.1f}% plain, "
            f"{100 * row['efficiency_against_busy_reference_of_medians']:.1f}% against the busy reference"
            for row in rows))


def plot(results: dict, path: Path) -> None:
    from pdemfem.plot import agg_pyplot

    plt = agg_pyplot()

    studies = [mode for mode in ("strong", "weak") if mode in results]
    figure, axes = plt.subplots(1, 2, figsize=(10, 4))
    for mode in studies:
        rows = results[mode]
        ranks = [row["ranks"] for row in rows]
        axes[0].plot(ranks, [row["particle_steps_per_second"] for row in rows], "o-", label=f"{mode}")
        base = rows[0]["particle_steps_per_second"] / rows[0]["ranks"]
        axes[0].plot(ranks, [base * r for r in ranks], ":", color="grey")
        axes[1].plot(ranks, [100 * row["efficiency"] for row in rows], "o-", label=f"{mode} efficiency")
        axes[1].plot(ranks, [100 * row["communication_share"] for row in rows], "s--", label=f"{mode} comm. share")
    axes[0].set_xlabel("ranks")
    axes[0].set_ylabel("particle-steps / s")
    axes[0].set_title("throughput (dotted: ideal)")
    axes[0].legend()
    axes[1].set_xlabel("ranks")
    axes[1].set_ylabel("%")
    axes[1].set_ylim(0, 110)
    axes[1].set_title("parallel efficiency, communication share")
    axes[1].legend()
    figure.tight_layout()
    figure.savefig(path, dpi=120)


def parse_arguments(argv=None):
    parser = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    parser.add_argument("--mode", choices=("strong", "weak", "both", "fem", "coupled"), default="both")
    parser.add_argument("--study", choices=("strong", "weak"), default="strong",
                        help="fem/coupled: strong (fixed size) or weak (size grows with the ranks)")
    parser.add_argument("--columns", type=int, default=40, help="fem/coupled: plate cells along x (per rank, weak)")
    parser.add_argument("--rows", type=int, default=20, help="fem/coupled: plate cells along y")
    parser.add_argument("--layers", type=int, default=2, help="fem/coupled: plate cells through the thickness")
    parser.add_argument("--particles", type=int, default=200000, help="strong scaling: total particles")
    parser.add_argument("--per-rank", type=int, default=50000, help="weak scaling: particles per rank")
    parser.add_argument("--ranks", type=int, nargs="+", default=[1, 2])
    parser.add_argument("--steps", type=int, default=300, help="timed steps")
    parser.add_argument("--rebalance-threshold", type=float, default=None,
                        help="the scene's parallel.rebalance_threshold (default: the scene default, 1.2)")
    parser.add_argument("--repeat", type=int, default=1,
                        help="runs per rank count, taken in turn; each row is the fastest (default 1)")
    parser.add_argument("--pre-steps", type=int, default=20, help="untimed steps after the build")
    parser.add_argument("--busy-reference", action="store_true",
                        help="strong: in every round also run as many one-rank copies side by side as the largest "
                             "rank count, and report the efficiency against that reference too")
    parser.add_argument("--spacing", type=float, default=COMPACT_SPACING,
                        help="lattice spacing [m] (default 2.04e-3; 2.4e-3 is settle.py's lattice, whose first "
                             "~1000 steps are free fall)")
    parser.add_argument("--json", type=Path, default=DEFAULT_JSON)
    parser.add_argument("--launcher", help="MPI launcher prefix, given '-n RANKS' (default: python -m "
                        "pdemfem.launch, i.e. mpiexec with pdemfem's environment); e.g. 'srun --cpu-bind=cores'")
    parser.add_argument(WORKER_FLAG, dest="worker_json", help=argparse.SUPPRESS)
    parser.add_argument("--core", type=int, default=None, help=argparse.SUPPRESS)
    return parser.parse_args(argv)


def main(argv=None) -> int:
    args = parse_arguments(argv)
    if args.worker_json:
        if args.mode in ("fem", "coupled"):
            import scaling_solids

            result = scaling_solids.worker(args)
        else:
            result = worker(args)
        if result:
            with open(args.worker_json, "w") as handle:
                json.dump(result, handle)
        return 0
    results = {"benchmark": "scaling", "started": time.strftime("%Y-%m-%d %H:%M:%S"),
               "machine": {"platform": platform.platform(), "cpus_available": len(os.sched_getaffinity(0)),
                           "load_average_1min_at_start": os.getloadavg()[0]},
               "scene": "benchmarks/scaling.py scene_dict (settle.py's scene)", "spacing": args.spacing,
               "steps": args.steps, "pre_steps": args.pre_steps}
    if args.mode in ("fem", "coupled"):
        results[f"{args.mode}_{args.study}"] = solids_study(args)
        path = args.json if args.json != DEFAULT_JSON else DEFAULT_JSON.with_name(f"scaling_{args.mode}.json")
        path.parent.mkdir(parents=True, exist_ok=True)
        path.write_text(json.dumps(results, indent=1))
        print(f"\nwrote {path}")
        return 0
    for mode in (("strong", "weak") if args.mode == "both" else (args.mode,)):
        results[mode] = study(mode, args)
        print_table(mode, results[mode])
    args.json.parent.mkdir(parents=True, exist_ok=True)
    with open(args.json, "w") as handle:
        json.dump(results, handle, indent=1)
    png = args.json.with_suffix(".png")
    plot(results, png)
    print(f"\nwrote {args.json} and {png}")
    return 0


if __name__ == "__main__":
    sys.exit(main())

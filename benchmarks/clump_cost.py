"""Cost per contact of 2-sphere clumps (dumbbells) against single spheres, same settle scene, same run.

    python benchmarks/clump_cost.py [--bodies 3000] [--pre-steps 16000] [--steps 1000] [--repeat 2]
                                    [--separation 1.2] [--phases]

Both scenes settle in the same box of five plane walls under gravity from a jittered lattice: one of
`--bodies` dumbbells (two spheres of radius r, centres `--separation` r apart: 1.2 overlapping, 2.0
touching; random orientations), one of 2 x `--bodies` single spheres of radius r (the same member
count).  After `--pre-steps` untimed steps (the grains land and pack) each times `--steps` steps; the
figure is the whole step's time per contact, ns.  The dumbbells' lattice is 1.6-2 times taller than the
spheres', so they land later: after the old default of 6000 steps (0.15 s) they were still landing (69
list rebuilds per 1000 steps against 8, 0.64 of the spheres' contacts per member); after 16000 (0.4 s)
both packs are at rest (no rebuild in 1000 steps).  The table gives the rebuilds of the timed steps.
Contacts are counted alike in both scenes: Simulation.contact_count(), the touching pairs of the
neighbour list plus the touching sphere-wall pairs, sampled every 100 steps (the two members of one
dumbbell are never a listed pair, so never a contact).  The two are timed alternately (`--repeat`
rounds, best of each) so a busy machine slows both alike; the CPU time of the same steps is reported
beside the wall time.  On a machine shared with other jobs the best round can still catch one scene in
a busy spell, so the figure of each scene's fastest 100 steps (over all rounds) is printed as well: the
one least touched by other work.  Writes benchmarks/results/clump_cost.json (clump_cost_<separation>.json for
another separation).

--phases also prints where the step's CPU time goes, per step of each scene (the pair kernel, the
walls, the list rebuilds with the neighbour list build and the clumps' member refresh inside them, the
integration passes: the sphere kicks or the clumps' first half, load sum and second half -- within
Simulation.step the last two only note their work as pending and the next first half does it,
docs/shapes.md; the rest is the step's Python and the wall/contributor bookkeeping).  The timers wrap
the solver's own functions and cost two clock reads per call, so the figures of a --phases run are a
little higher than without.
"""
from __future__ import annotations

import argparse
import json
import time
from pathlib import Path

import numpy as np

HERE = Path(__file__).resolve().parent
RADIUS = 1.0e-3


def scene(bodies: int, clumps: bool, separation: float = 1.2) -> dict:
    members = 2 * bodies
    # A dumbbell spans (separation + 2) r: room for any orientation (1.6 x the spheres' at 1.2 r).
    spacing = 2.4 * RADIUS * ((separation + 2.0) / 2.0 if clumps else 1.0)
    count = bodies if clumps else members
    side = max(4, int(np.ceil((count / 2.0) ** (1.0 / 3.0))))  # a box twice as tall as wide
    width = side * spacing
    height = 2 * side * spacing
    group = {"name": "grains", "material": "glass",
             "insert": {"kind": "lattice", "region": {"box": [[0, 0, 0], [width, width, height]]},
                        "count": count, "spacing": spacing, "jitter": 0.2, "seed": 3}}
    if clumps:
        half = 0.5 * separation * RADIUS
        group["clump"] = {"spheres": [{"position": [-half, 0, 0], "radius": RADIUS},
                                      {"position": [half, 0, 0], "radius": RADIUS}]}
    else:
        group["radius"] = RADIUS
    walls = [{"name": "floor", "kind": "plane", "point": [0, 0, 0], "normal": [0, 0, 1], "material": "glass"}]
    for name, point, normal in (("x0", [0, 0, 0], [1, 0, 0]), ("x1", [width, 0, 0], [-1, 0, 0]),
                                ("y0", [0, 0, 0], [0, 1, 0]), ("y1", [0, width, 0], [0, -1, 0])):
        walls.append({"name": name, "kind": "plane", "point": point, "normal": normal, "material": "glass"})
    return {"time": {"end": 1.0, "dt": 2.5e-5}, "gravity": [0, 0, -9.81],
            "materials": {"glass": {"density": 2500, "youngs_modulus": 5e6, "poisson_ratio": 0.3}},
            "interactions": {"default": {"model": "hertz_mindlin", "restitution": 0.5, "friction": 0.5}},
            "particles": [group], "walls": walls, "output": {"every": 1.0, "particles": [], "solids": []}}


PHASE_TIMES: dict = {}
PHASE_CALLS: dict = {}


def _timed_call(function, label):
    def timed_function(*args, **kwargs):
        start = time.process_time()
        try:
            return function(*args, **kwargs)
        finally:
            PHASE_TIMES[label] = PHASE_TIMES.get(label, 0.0) + time.process_time() - start
            PHASE_CALLS[label] = PHASE_CALLS.get(label, 0) + 1
    return timed_function


# (owner, attribute, label): module functions the step calls by their module-level name, and methods.
def _phase_targets():
    from pdemfem.clumps.bodies import ClumpBodies
    from pdemfem.neighbors.verlet import VerletList
    from pdemfem.particles import system
    return [(system.ParticleSystem, "_rebuild", "rebuild"), (VerletList, "build", "  neighbour list build"),
            (ClumpBodies, "refresh_rows", "  member refresh"),
            (system, "kick_drift", "sphere kick+drift"), (system, "kick", "sphere kick"),
            (ClumpBodies, "first_half", "clump first half"), (ClumpBodies, "sum_loads", "clump load sum"),
            (ClumpBodies, "second_half", "clump second half")]


def install_phase_timers() -> None:
    from pdemfem.particles import system

    for owner, name, label in _phase_targets():
        setattr(owner, name, _timed_call(getattr(owner, name), label))
    # The contact kernels are those compiled for the scene's composition (pdemfem.contact.specialized): time
    # them in the module the particle system gets (one module per composition, shared by both scenes).
    kernels_for = system.contact_kernels
    wrapped = set()

    def timed_kernels(composition):
        module = kernels_for(composition)
        if module.__name__ not in wrapped:
            wrapped.add(module.__name__)
            module.pair_forces = _timed_call(module.pair_forces, "pair kernel")
            module.plane_wall_forces = _timed_call(module.plane_wall_forces, "walls")
        return module
    system.contact_kernels = timed_kernels


def timed(simulation, steps: int) -> tuple:
    """(wall seconds, CPU seconds, mean contact count, wall seconds of the fastest 100 steps) of `steps`
    steps."""
    contacts, elapsed, cpu, fastest = [], 0.0, 0.0, np.inf
    for _ in range(max(1, steps // 100)):
        start, start_cpu = time.perf_counter(), time.process_time()
        simulation.step(100)
        window = time.perf_counter() - start
        elapsed += window
        fastest = min(fastest, window)
        cpu += time.process_time() - start_cpu
        contacts.append(simulation.contact_count())
    return elapsed, cpu, float(np.mean(contacts)), fastest


def print_phases(phases: dict, steps: int, members: dict) -> None:
    """CPU us per step by phase (mean of the rounds), for both scenes, and the clumps' share per member
    relative to the spheres'."""
    print(f"CPU time by phase, us per step (mean of the rounds; calls per {steps} steps)")
    print(f"{'':24} {'spheres':>9} {'calls':>6} {'clumps':>9} {'calls':>6}")
    labels = ["pair kernel", "walls"] + [label for _, _, label in _phase_targets()]
    totals = {kind: phases[kind].get("whole step", {"seconds": 0.0})["seconds"] for kind in phases}
    for kind in phases:
        top = sum(row["seconds"] for label, row in phases[kind].items()
                  if label != "whole step" and not label.startswith("  "))
        phases[kind]["rest"] = {"seconds": totals[kind] - top, "calls": steps}
    for label in labels + ["rest", "whole step"]:
        cells = []
        for kind in ("spheres", "clumps"):
            row = phases[kind].get(label)
            cells.append(f"{1e6 * row['seconds'] / steps:9.1f} {row['calls']:6.0f}" if row else f"{'-':>9} {'':6}")
        print(f"{label:24} {cells[0]} {cells[1]}")
    if totals["spheres"] > 0:
        per_member = (totals["clumps"] / members["clumps"]) / (totals["spheres"] / members["spheres"])
        print(f"clump step per member sphere / sphere step per sphere: {per_member:.2f}")


def main(argv=None) -> int:
    import tempfile

    from pdemfem import Simulation

    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("--bodies", type=int, default=3000)
    parser.add_argument("--pre-steps", type=int, default=16000)
    parser.add_argument("--steps", type=int, default=1000)
    parser.add_argument("--repeat", type=int, default=2)
    parser.add_argument("--separation", type=float, default=1.2,
                        help="distance of the dumbbell's sphere centres in radii (1.2 overlapping, 2.0 touching)")
    parser.add_argument("--json", type=Path, default=None)
    parser.add_argument("--phases", action="store_true", help="also print the step's CPU time by phase")
    args = parser.parse_args(argv)
    if args.phases:
        install_phase_timers()
    if args.json is None:
        name = "clump_cost.json" if args.separation == 1.2 else f"clump_cost_{args.separation:g}.json"
        args.json = HERE / "results" / name
    simulations = {}
    for kind in ("spheres", "clumps"):
        folder = Path(tempfile.mkdtemp())
        simulations[kind] = Simulation.from_dict(scene(args.bodies, kind == "clumps", args.separation),
                                                 base_dir=folder, output_dir=folder / "out")
        simulations[kind].step(args.pre_steps)
    best = {kind: None for kind in simulations}
    phases = {kind: {} for kind in simulations}
    fastest_window = {}  # ns per contact of each scene's fastest 100 steps, over all rounds
    for _ in range(args.repeat):
        for kind, simulation in simulations.items():
            PHASE_TIMES.clear()
            PHASE_CALLS.clear()
            builds = simulation.particle_system.neighbors.builds
            elapsed, cpu, contacts, fastest = timed(simulation, args.steps)
            window = 1e9 * fastest / (100 * contacts)
            if kind not in fastest_window or window < fastest_window[kind]:
                fastest_window[kind] = window
            builds = simulation.particle_system.neighbors.builds - builds
            if args.phases:
                for label, seconds in PHASE_TIMES.items():
                    row = phases[kind].setdefault(label, {"seconds": 0.0, "calls": 0})
                    row["seconds"] += seconds / args.repeat
                    row["calls"] += PHASE_CALLS[label] / args.repeat
                row = phases[kind].setdefault("whole step", {"seconds": 0.0, "calls": 0})
                row["seconds"] += cpu / args.repeat
                row["calls"] += args.steps / args.repeat
            per_contact = 1e9 * elapsed / (args.steps * contacts)
            if best[kind] is None or per_contact < best[kind]["ns_per_contact"]:
                best[kind] = {"ns_per_contact": per_contact, "seconds": elapsed, "cpu_seconds": cpu,
                              "cpu_ns_per_contact": 1e9 * cpu / (args.steps * contacts), "mean_contacts": contacts,
                              "members": int(simulation.particle_count()), "rebuilds": builds}
    ratio = best["clumps"]["ns_per_contact"] / best["spheres"]["ns_per_contact"]
    step_ratio = best["clumps"]["seconds"] / best["spheres"]["seconds"]
    print(f"dumbbells of centres {args.separation:g} r apart against single spheres")
    print(f"{'':10} {'members':>8} {'contacts':>9} {'per member':>10} {'s / step':>10} {'ns / contact':>13} "
          f"{'CPU ns / contact':>17} {'rebuilds':>8}")
    for kind, row in best.items():
        print(f"{kind:10} {row['members']:8d} {row['mean_contacts']:9.0f} "
              f"{row['mean_contacts'] / row['members']:10.2f} {row['seconds'] / args.steps:10.2e} "
              f"{row['ns_per_contact']:13.1f} {row['cpu_ns_per_contact']:17.1f} {row['rebuilds']:8d}")
    print(f"clumps / spheres: per step {step_ratio:.2f}, per contact {ratio:.2f} (target <= 1.3)")
    window_ratio = fastest_window["clumps"] / fastest_window["spheres"]
    print(f"fastest 100 steps: {fastest_window['spheres']:.1f} and {fastest_window['clumps']:.1f} ns per contact, "
          f"clumps / spheres {window_ratio:.2f}")
    if args.phases:
        print_phases(phases, args.steps, {kind: best[kind]["members"] for kind in best})
    args.json.parent.mkdir(parents=True, exist_ok=True)
    result = {"bodies": args.bodies, "pre_steps": args.pre_steps, "steps": args.steps,
              "separation": args.separation, "results": best, "ratio": ratio, "step_ratio": step_ratio,
              "fastest_100_steps_ns_per_contact": fastest_window, "fastest_100_steps_ratio": window_ratio}
    if args.phases:
        result["phases_cpu_seconds_mean_of_rounds"] = phases
    args.json.write_text(json.dumps(result, indent=2))
    return 0


if __name__ == "__main__":
    raise SystemExit(main())

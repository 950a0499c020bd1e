"""Cost per contact of 2-sphere clumps (dumbbells) against single spheres, same settle scene, same run.

    python benchmarks/clump_cost.py [--bodies 3000] [--pre-steps 6000] [--steps 1000] [--repeat 2]
                                    [--separation 1.2]

Both scenes settle in the same box of five plane walls under gravity from a jittered lattice: one of
`--bodies` dumbbells (two spheres of radius r, centres `--separation` r apart: 1.2 overlapping, 2.0
touching; random orientations), one of 2 x `--bodies` single spheres of radius r (the same member
count).  After `--pre-steps` untimed steps (the grains land and pack) each times `--steps` steps; the
figure is the whole step's time per contact, ns.  Contacts are counted alike in both scenes:
Simulation.contact_count(), the touching pairs of the neighbour list plus the touching sphere-wall
pairs, sampled every 100 steps (the two members of one dumbbell are never a listed pair, so never a
contact).  The two are timed alternately (`--repeat` rounds, best of each) so a busy machine slows both
alike; the CPU time of the same steps is reported beside the wall time.  Writes
benchmarks/results/clump_cost.json (clump_cost_<separation>.json for another separation).
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


def timed(simulation, steps: int) -> tuple:
    """(wall seconds, CPU seconds, mean contact count) of `steps` steps."""
    contacts, elapsed, cpu = [], 0.0, 0.0
    for _ in range(max(1, steps // 100)):
        start, start_cpu = time.perf_counter(), time.process_time()
        simulation.step(100)
        elapsed += time.perf_counter() - start
        cpu += time.process_time() - start_cpu
        contacts.append(simulation.contact_count())
    return elapsed, cpu, float(np.mean(contacts))


def main(argv=None) -> int:
    import tempfile

    from pdemfem import Simulation

    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("--bodies", type=int, default=3000)
    parser.add_argument("--pre-steps", type=int, default=6000)
    parser.add_argument("--steps", type=int, default=1000)
    parser.add_argument("--repeat", type=int, default=2)
    parser.add_argument("--separation", type=float, default=1.2,
                        help="distance of the dumbbell's sphere centres in radii (1.2 overlapping, 2.0 touching)")
    parser.add_argument("--json", type=Path, default=None)
    args = parser.parse_args(argv)
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
    for _ in range(args.repeat):
        for kind, simulation in simulations.items():
            elapsed, cpu, contacts = timed(simulation, args.steps)
            per_contact = 1e9 * elapsed / (args.steps * contacts)
            if best[kind] is None or per_contact < best[kind]["ns_per_contact"]:
                best[kind] = {"ns_per_contact": per_contact, "seconds": elapsed, "cpu_seconds": cpu,
                              "cpu_ns_per_contact": 1e9 * cpu / (args.steps * contacts), "mean_contacts": contacts,
                              "members": int(simulation.particle_count())}
    ratio = best["clumps"]["ns_per_contact"] / best["spheres"]["ns_per_contact"]
    step_ratio = best["clumps"]["seconds"] / best["spheres"]["seconds"]
    print(f"dumbbells of centres {args.separation:g} r apart against single spheres")
    print(f"{'':10} {'members':>8} {'contacts':>9} {'per member':>10} {'s / step':>10} {'ns / contact':>13} "
          f"{'CPU ns / contact':>17}")
    for kind, row in best.items():
        print(f"{kind:10} {row['members']:8d} {row['mean_contacts']:9.0f} "
              f"{row['mean_contacts'] / row['members']:10.2f} {row['seconds'] / args.steps:10.2e} "
              f"{row['ns_per_contact']:13.1f} {row['cpu_ns_per_contact']:17.1f}")
    print(f"clumps / spheres: per step {step_ratio:.2f}, per contact {ratio:.2f} (target <= 1.3)")
    args.json.parent.mkdir(parents=True, exist_ok=True)
    args.json.write_text(json.dumps({"bodies": args.bodies, "pre_steps": args.pre_steps, "steps": args.steps,
                                     "separation": args.separation, "results": best, "ratio": ratio,
                                     "step_ratio": step_ratio}, indent=2))
    return 0


if __name__ == "__main__":
    raise SystemExit(main())

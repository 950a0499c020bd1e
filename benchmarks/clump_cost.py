"""Cost per contact of 2-sphere clumps (dumbbells) against single spheres, same settle scene, same run.

    python benchmarks/clump_cost.py [--bodies 3000] [--pre-steps 6000] [--steps 1000] [--repeat 2]

Both scenes settle in the same box of five plane walls under gravity from a jittered lattice: one of
`--bodies` dumbbells (two overlapping spheres of radius r, centres 1.2 r apart, random orientations),
one of 2 x `--bodies` single spheres of radius r (the same member count).  After `--pre-steps` untimed
steps (the grains land and pack) each times `--steps` steps; the figure is the whole step's time per
contact (pairs + walls, sampled every 100 steps), ns.  The two are timed alternately (`--repeat` rounds,
best of each) so a busy machine slows both alike.  Writes benchmarks/results/clump_cost.json.
"""
from __future__ import annotations

import argparse
import json
import time
from pathlib import Path

import numpy as np

HERE = Path(__file__).resolve().parent
RADIUS = 1.0e-3


def scene(bodies: int, clumps: bool) -> dict:
    members = 2 * bodies
    spacing = 2.4 * RADIUS * (1.6 if clumps else 1.0)  # a dumbbell spans 3.2 r: room for any orientation
    count = bodies if clumps else members
    side = max(4, int(np.ceil((count / 2.0) ** (1.0 / 3.0))))  # a box twice as tall as wide
    width = side * spacing
    height = 2 * side * spacing
    group = {"name": "grains", "material": "glass",
             "insert": {"kind": "lattice", "region": {"box": [[0, 0, 0], [width, width, height]]},
                        "count": count, "spacing": spacing, "jitter": 0.2, "seed": 3}}
    if clumps:
        group["clump"] = {"spheres": [{"position": [-0.6 * RADIUS, 0, 0], "radius": RADIUS},
                                      {"position": [0.6 * RADIUS, 0, 0], "radius": RADIUS}]}
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
    contacts, elapsed = [], 0.0
    for _ in range(max(1, steps // 100)):
        start = time.perf_counter()
        simulation.step(100)
        elapsed += time.perf_counter() - start
        contacts.append(simulation.contact_count())
    return elapsed, float(np.mean(contacts))


def main(argv=None) -> int:
    import tempfile

    from pdemfem import Simulation

    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("--bodies", type=int, default=3000)
    parser.add_argument("--pre-steps", type=int, default=6000)
    parser.add_argument("--steps", type=int, default=1000)
    parser.add_argument("--repeat", type=int, default=2)
    parser.add_argument("--json", type=Path, default=HERE / "results" / "clump_cost.json")
    args = parser.parse_args(argv)
    simulations = {}
    for kind in ("spheres", "clumps"):
        folder = Path(tempfile.mkdtemp())
        simulations[kind] = Simulation.from_dict(scene(args.bodies, kind == "clumps"), base_dir=folder,
                                                 output_dir=folder / "out")
        simulations[kind].step(args.pre_steps)
    best = {kind: None for kind in simulations}
    for _ in range(args.repeat):
        for kind, simulation in simulations.items():
            elapsed, contacts = timed(simulation, args.steps)
            per_contact = 1e9 * elapsed / (args.steps * contacts)
            if best[kind] is None or per_contact < best[kind]["ns_per_contact"]:
                best[kind] = {"ns_per_contact": per_contact, "seconds": elapsed, "mean_contacts": contacts,
                              "members": int(simulation.particle_count())}
    ratio = best["clumps"]["ns_per_contact"] / best["spheres"]["ns_per_contact"]
    print(f"{'':22} {'members':>8} {'contacts':>9} {'s / step':>10} {'ns / contact':>13}")
    for kind, row in best.items():
        print(f"{kind:22} {row['members']:8d} {row['mean_contacts']:9.0f} {row['seconds'] / args.steps:10.2e} "
              f"{row['ns_per_contact']:13.1f}")
    print(f"clumps / spheres, ns per contact: {ratio:.2f} (target <= 1.3)")
    args.json.parent.mkdir(parents=True, exist_ok=True)
    args.json.write_text(json.dumps({"bodies": args.bodies, "pre_steps": args.pre_steps, "steps": args.steps,
                                     "results": best, "ratio": ratio}, indent=2))
    return 0


if __name__ == "__main__":
    raise SystemExit(main())

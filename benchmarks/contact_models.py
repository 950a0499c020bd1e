"""What each contact sub-model costs, and how JKR adhesion changes the restitution.

    python benchmarks/contact_models.py [--particles 4000] [--pre-steps 1500] [--steps 1500] [--repeat 2]

Part 1 (cost).  The settle benchmark's scene (benchmarks/settle.py: glass spheres poured into a box of
plane walls) with each interaction variant: after --pre-steps (a bed with contacts), --steps are timed
(best of --repeat, one process, same run).  Printed: wall time per step, contacts per step and the
step time per contact relative to the first row.

Part 2 (JKR restitution).  Two equal spheres (R 1 mm, E 1e6 Pa, rho 1000) collide head-on at speed v
with model jkr, restitution 0.5 and W = 0.05 J/m^2; printed: the rebound ratio (relative speed after /
before; 0 = stuck) against v.  The dashpot is calibrated for Hertz (no adhesion), so at high speed the
ratio tends to the asked 0.5; below a sticking speed adhesion holds the spheres together.

Results go to benchmarks/results/contact_models.json.
"""
from __future__ import annotations

import argparse
import json
import math
import sys
import tempfile
import time
from pathlib import Path

import numpy as np

sys.path.insert(0, str(Path(__file__).resolve().parent))
import settle  # noqa: E402

from pdemfem import Simulation  # noqa: E402

VARIANTS = [
    ("hertz_mindlin, friction 0.5 (settle default)", {}),
    ("hertz_mindlin, frictionless (no tangential history)", {"friction": 0.0}),
    ("+ rolling constant_torque, mu_r 0.1", {"rolling_friction": 0.1, "rolling_model": "constant_torque"}),
    ("+ rolling elastic_plastic, mu_r 0.1", {"rolling_friction": 0.1, "rolling_model": "elastic_plastic"}),
    ("linear_spring_dashpot, friction 0.5", {"model": "linear_spring_dashpot"}),
    ("jkr W 0.02 J/m^2, friction 0.5", {"model": "jkr", "work_of_adhesion": 0.02}),
]


def time_variant(changes: dict, args) -> dict:
    scene = settle.scene_dict(args.particles)
    scene["interactions"]["default"].update(changes)
    with tempfile.TemporaryDirectory() as directory:
        sim = Simulation.from_dict(scene, output_dir=directory)
        sim.step(args.pre_steps)
        best = math.inf
        contacts = []
        for _ in range(args.repeat):
            start = time.perf_counter()
            for _ in range(args.steps // 10):
                sim.step(10)
                contacts.append(sim.particle_system.contact_count)
            best = min(best, (time.perf_counter() - start) / (10 * (args.steps // 10)))
        width = sim.particle_system.tables.history_width
    return {"seconds_per_step": best, "contacts_per_step": float(np.mean(contacts)), "history_columns": width}


def jkr_rebound(speed: float) -> float:
    radius, work = 1.0e-3, 0.05
    material = {"density": 1000.0, "youngs_modulus": 1.0e6, "poisson_ratio": 0.3}
    gap = 2.0 * radius + 1e-6
    scene = {
        "time": {"end": 1.0, "dt": "auto", "expected_impact_speed": speed},
        "materials": {"soft": material},
        "interactions": {"default": {"model": "jkr", "work_of_adhesion": work, "restitution": 0.5,
                                     "friction": 0.0}},
        "particles": [{"name": "pair", "material": "soft", "radius": radius,
                       "insert": {"kind": "list", "positions": [[0, 0, 0], [gap, 0, 0]],
                                  "velocities": [[speed / 2, 0, 0], [-speed / 2, 0, 0]]}}],
    }
    with tempfile.TemporaryDirectory() as directory:
        sim = Simulation.from_dict(scene, output_dir=directory)
        # Long enough for contact and separation (or for the sticking to settle): 40 Hertz contact times.
        duration = 40 * 2.868 * ((4 / 3 * math.pi * radius ** 3 * 1000 / 2) ** 2
                                 / (radius / 2 * (material["youngs_modulus"] / (2 * 0.91)) ** 2 * speed)) ** 0.2
        sim.step(max(1, int(duration / sim.dt)))
        velocities = sim.particles.velocities
        relative = velocities[0, 0] - velocities[1, 0]
        return max(0.0, -relative / speed) if sim.particle_system.contact_count == 0 else 0.0


def main(argv=None) -> int:
    parser = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    parser.add_argument("--particles", type=int, default=4000)
    parser.add_argument("--pre-steps", type=int, default=1500)
    parser.add_argument("--steps", type=int, default=1500)
    parser.add_argument("--repeat", type=int, default=2)
    parser.add_argument("--json", type=Path, default=Path(__file__).parent / "results" / "contact_models.json")
    args = parser.parse_args(argv)

    costs = []
    for name, changes in VARIANTS:
        result = time_variant(changes, args)
        costs.append({"variant": name, **result})
    base = costs[0]["seconds_per_step"] / max(costs[0]["contacts_per_step"], 1.0)
    print(f"\nCost of the contact sub-models: {args.particles} spheres, {args.steps} timed steps after "
          f"{args.pre_steps}, best of {args.repeat}, one process")
    print(f"{'variant':52s} {'us/step':>9s} {'contacts':>9s} {'history':>8s} {'per contact':>12s}")
    for row in costs:
        per_contact = row["seconds_per_step"] / max(row["contacts_per_step"], 1.0)
        row["relative_per_contact"] = per_contact / base
        print(f"{row['variant']:52s} {1e6 * row['seconds_per_step']:9.1f} {row['contacts_per_step']:9.0f} "
              f"{row['history_columns']:8d} {row['relative_per_contact']:12.3f}")

    speeds = [0.003, 0.01, 0.03, 0.1, 0.3, 1.0, 3.0]
    rebounds = [{"speed": v, "rebound_ratio": jkr_rebound(v)} for v in speeds]
    print("\nJKR (W 0.05 J/m^2, R 1 mm, E 1e6 Pa, asked restitution 0.5): rebound ratio vs impact speed")
    print(f"{'speed [m/s]':>12s} {'rebound':>8s}")
    for row in rebounds:
        print(f"{row['speed']:12.3g} {row['rebound_ratio']:8.3f}")
    args.json.parent.mkdir(parents=True, exist_ok=True)
    args.json.write_text(json.dumps({"arguments": {k: str(v) for k, v in vars(args).items()}, "costs": costs,
                                     "jkr_restitution": rebounds}, indent=2))
    return 0


if __name__ == "__main__":
    sys.exit(main())

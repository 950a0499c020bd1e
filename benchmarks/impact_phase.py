"""Single-impact restitution against the start phase, at dt auto and at half of it.

    .venv/bin/python benchmarks/impact_phase.py
    .venv/bin/python benchmarks/impact_phase.py --models linear_spring_dashpot --restitutions 0.5 --phases 24

Two 5 mm spheres closing head-on at 1 m/s (no gravity, no friction); the start gap moves the first touch
through a step (12 phases by default).  Prints, per law, material and restitution, the mean and the range of
the measured restitution's relative error over the phases (docs/restitution.md), and writes them to JSON.
"""
from __future__ import annotations

import argparse
import json
import logging
from pathlib import Path

import numpy as np

MATERIALS = {"rubber": (1100, 5e6, 0.45), "steel": (7850, 2e11, 0.3)}
RADIUS, SPEED = 0.005, 0.5  # each sphere's speed: 1 m/s closing


def impact(material: str, restitution: float, model: str, gap: float, halve: bool) -> tuple:
    """(measured restitution, steps in contact) of one impact starting `gap` apart."""
    from pdemfem import Simulation

    density, modulus, poisson = MATERIALS[material]
    scene = {"time": {"end": 1.0, "dt": "auto"}, "gravity": [0, 0, 0],
             "materials": {material: {"density": density, "youngs_modulus": modulus, "poisson_ratio": poisson}},
             "interactions": {"default": {"model": model, "restitution": restitution, "friction": 0.0}},
             "particles": [{"name": "pair", "material": material, "radius": RADIUS,
                            "insert": {"kind": "list", "positions": [[0, 0, 0], [2 * RADIUS + gap, 0, 0]],
                                       "velocities": [[SPEED, 0, 0], [-SPEED, 0, 0]]}}],
             "output": {"particles": [], "solids": []}}
    sim = Simulation.from_dict(scene)
    if halve:
        scene["time"]["dt"] = 0.5 * sim.dt
        sim = Simulation.from_dict(scene)
    steps, started = 0, False
    while not started or sim.contact_count():
        sim.step(1)
        touching = bool(sim.contact_count())
        steps += touching
        started = started or touching
    velocities = sim.particles.velocities[np.argsort(sim.particles.ids), 0]
    return (velocities[1] - velocities[0]) / (2 * SPEED), steps


def main(argv=None) -> None:
    parser = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    parser.add_argument("--models", nargs="+", default=["linear_spring_dashpot", "hertz_mindlin"])
    parser.add_argument("--materials", nargs="+", default=list(MATERIALS), choices=list(MATERIALS))
    parser.add_argument("--restitutions", nargs="+", type=float, default=[0.05, 0.5, 0.9])
    parser.add_argument("--phases", type=int, default=12)
    parser.add_argument("--json", default=str(Path(__file__).parent / "results" / "impact_phase.json"))
    arguments = parser.parse_args(argv)
    logging.disable(logging.WARNING)
    rows = []
    print(f"{'law':22s} {'material':8s} {'e':>5s} {'dt':>5s} {'steps':>6s} {'mean %':>8s} {'min %':>8s} {'max %':>8s}")
    for model in arguments.models:
        for material in arguments.materials:
            for restitution in arguments.restitutions:
                for halve in (False, True):
                    errors, steps = [], 0
                    for k in range(arguments.phases):
                        gap = 1e-4 * (1.0 + 0.37 * k / arguments.phases)  # 0.37 gaps: more than a step's travel
                        measured, steps = impact(material, restitution, model, gap, halve)
                        errors.append(100.0 * (measured / restitution - 1.0))
                    row = {"model": model, "material": material, "restitution": restitution,
                           "dt": "auto/2" if halve else "auto", "steps": steps, "mean_percent": float(np.mean(errors)),
                           "min_percent": float(np.min(errors)), "max_percent": float(np.max(errors))}
                    rows.append(row)
                    print(f"{model:22s} {material:8s} {restitution:5.2f} {row['dt']:>6s} {steps:6d} "
                          f"{row['mean_percent']:+8.2f} {row['min_percent']:+8.2f} {row['max_percent']:+8.2f}",
                          flush=True)
    Path(arguments.json).parent.mkdir(parents=True, exist_ok=True)
    Path(arguments.json).write_text(json.dumps({"rows": rows}, indent=1))
    print(f"results: {arguments.json}")


if __name__ == "__main__":
    main()

"""What heat conduction costs on the settle benchmark's scene, heat off against heat on, same run.

    python benchmarks/heat_cost.py [--particles 28000] [--pre-steps 6000] [--steps 1000] [--repeat 3]

The settle scene (benchmarks/settle.py: glass spheres settling in a box of five plane walls) twice:
as it is (no thermal key: no temperature allocated, no conduction computed), and with heat on (the
grains at 300 K with k = 1 W/(m K), c = 800 J/(kg K), the floor held at 400 K).  Both are built
first, stepped --pre-steps (a settled bed: the figure that matters is the cost per contact of a
packed bed), then timed alternately --repeat times in chunks of --steps, keeping each one's best.
Printed: seconds per step, contacts, and heat-on / heat-off.  Results go to
benchmarks/results/heat_cost.json.
"""
from __future__ import annotations

import argparse
import json
import math
import sys
import tempfile
import time
from pathlib import Path

sys.path.insert(0, str(Path(__file__).resolve().parent))
import settle  # noqa: E402

from pdemfem import Simulation  # noqa: E402

DEFAULT_JSON = Path(__file__).resolve().parent / "results" / "heat_cost.json"


def heated(scene: dict) -> dict:
    scene["materials"]["glass"].update(conductivity=1.0, heat_capacity=800.0)
    scene["particles"][0]["initial_temperature"] = 300.0
    scene["walls"][0]["temperature"] = 400.0
    return scene


def main(argv=None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    parser.add_argument("--particles", type=int, default=settle.REFERENCE_PARTICLES)
    parser.add_argument("--pre-steps", type=int, default=6000, help="untimed steps (a settled bed)")
    parser.add_argument("--steps", type=int, default=1000, help="timed steps per attempt")
    parser.add_argument("--repeat", type=int, default=3, help="alternating attempts; the best of each is kept")
    parser.add_argument("--json", type=Path, default=DEFAULT_JSON)
    args = parser.parse_args(argv)
    variants = {"heat off": settle.scene_dict(args.particles), "heat on": heated(settle.scene_dict(args.particles))}
    with tempfile.TemporaryDirectory() as directory:
        simulations = {name: Simulation.from_dict(scene, output_dir=f"{directory}/{index}")
                       for index, (name, scene) in enumerate(variants.items())}
        for name, sim in simulations.items():
            print(f"{name}: {args.pre_steps} untimed steps ...", flush=True)
            sim.step(args.pre_steps)
        best = {name: math.inf for name in simulations}
        for attempt in range(args.repeat):
            for name, sim in simulations.items():
                start = time.perf_counter()
                sim.step(args.steps)
                best[name] = min(best[name], (time.perf_counter() - start) / args.steps)
        contacts = {name: sim.contact_count() for name, sim in simulations.items()}
        temperatures = simulations["heat on"].particles.temperatures
    results = {"benchmark": "heat_cost", "particles": args.particles, "pre_steps": args.pre_steps,
               "steps": args.steps, "repeat": args.repeat,
               "seconds_per_step": best, "contacts": contacts,
               "heat_on_over_off": best["heat on"] / best["heat off"],
               "hottest_particle_K": float(temperatures.max())}
    print(f"\n{'variant':<10} {'s/step':>10} {'contacts':>9}")
    for name in simulations:
        print(f"{name:<10} {best[name]:>10.4g} {contacts[name]:>9d}")
    print(f"heat on / heat off: {results['heat_on_over_off']:.3f} (the same bed: contacts differ only by the "
          f"run's own round-off)")
    args.json.parent.mkdir(parents=True, exist_ok=True)
    args.json.write_text(json.dumps(results, indent=2))
    print(f"results: {args.json}")
    return 0


if __name__ == "__main__":
    sys.exit(main())

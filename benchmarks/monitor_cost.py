"""Cost of the run monitor's check (pdemfem.monitor) against the step it guards.

    .venv/bin/python benchmarks/monitor_cost.py
    .venv/bin/python benchmarks/monitor_cost.py --counts 10 3000 20000

Random beds of 1 mm soft glass beads falling onto a floor (dt: auto), timed after 200 steps.
`run` checks at every output step and at every stop check (every STOP_CHECK_EVERY = 100 steps),
so the share of the stepping is one check / (100 steps).
"""
from __future__ import annotations

import argparse
import tempfile
import time


def scene(count: int) -> dict:
    box = 0.01 * max(1.0, (count / 10.0) ** (1.0 / 3.0)) * 0.6  # ~10 % solid fraction
    return {"time": {"end": 1.0, "dt": "auto"}, "gravity": [0, 0, -9.81],
            "materials": {"glass": {"density": 2500, "youngs_modulus": 5.0e6, "poisson_ratio": 0.3}},
            "interactions": {"default": {"restitution": 0.5, "friction": 0.5}},
            "particles": [{"name": "beads", "material": "glass", "radius": 0.001,
                           "insert": {"kind": "random", "region": {"box": [[0, 0, 0], [box, box, box]]},
                                      "count": count, "seed": 1}}],
            "walls": [{"name": "floor", "kind": "plane", "point": [0, 0, 0], "normal": [0, 0, 1],
                       "material": "glass"}]}


def main(argv=None):
    from pdemfem import Simulation
    from pdemfem.io.signals import STOP_CHECK_EVERY
    from pdemfem.monitor import DivergenceMonitor

    parser = argparse.ArgumentParser(description=__doc__)
    parser.add_argument("--counts", type=int, nargs="+", default=[10, 3000])
    parser.add_argument("--checks", type=int, default=2000)
    arguments = parser.parse_args(argv)
    print(f"{'particles':>9} {'step [us]':>10} {'check [us]':>11} {'share of stepping':>18}")
    with tempfile.TemporaryDirectory() as folder:
        for count in arguments.counts:
            simulation = Simulation.from_dict(scene(count), base_dir=folder, output_dir=f"{folder}/out")
            simulation.step(200)
            steps = max(100, 400000 // max(count, 1))
            start = time.perf_counter()
            simulation.step(steps)
            step_time = (time.perf_counter() - start) / steps
            monitor = DivergenceMonitor(simulation)
            monitor.start()
            start = time.perf_counter()
            for _ in range(arguments.checks):
                monitor.check()
            check_time = (time.perf_counter() - start) / arguments.checks
            share = check_time / (STOP_CHECK_EVERY * step_time)
            print(f"{count:>9} {step_time * 1e6:>10.1f} {check_time * 1e6:>11.1f} {100 * share:>17.2f}%")


if __name__ == "__main__":
    main()

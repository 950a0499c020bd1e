"""The point-load limit of the coupled contact: energy of a heavy sphere on a yielding block under refinement.

The resting case of tests/stability_cases.py (sphere R = 0.2 m, 335 kg, at rest on a clamped 1 x 1 x 0.5 m
block meshed n x n x n/2) with a soft block (E = 1e6 Pa: the contact's stiffness against the surface's,
S_n/(E l), is 0.63 at n = 4 and doubles with n), restitution 1 and no friction, so nothing dissipates.  Printed
per case: the smallest and largest change of the mechanical energy over the run at the particles' time level
(stability_cases.LevelEnergy, exact without FE sub-steps), velocity Verlet's bound on the resting contact's
oscillation, and the sampled series.  `--slide v` starts the sphere sliding along x at v m/s from x = 0.3 m.

    python benchmarks/coupled_point_load.py                       # P1, n = 4 8 16 32, 1 s (~2 min)
    python benchmarks/coupled_point_load.py --element P2 --cells 4 8 16
    python benchmarks/coupled_point_load.py --cells 8 --slide 0.5 --end 0.6
docs/coupling.md ("Stability conditions", point load) quotes the results.
"""
from __future__ import annotations

import argparse
import sys
import tempfile
import time
from pathlib import Path

HERE = Path(__file__).resolve().parent
sys.path.insert(0, str(HERE.parent / "tests"))

import pdemfem  # noqa: E402,F401  (environment first)
from stability_cases import LevelEnergy, resting_scene, verlet_energy_bound  # noqa: E402

from pdemfem import Simulation  # noqa: E402
from pdemfem.errors import SolverError  # noqa: E402


def run_case(cells: int, element: str, modulus: float, restitution: float, dt: float, end: float, slide: float,
             transfer: str = "nearest"):
    scene = resting_scene(cells, element=element, restitution=restitution, dt=dt, end=end)
    scene["coupling"]["transfer"] = transfer
    scene["materials"]["steel"]["youngs_modulus"] = modulus
    if slide:
        scene["particles"][0]["insert"]["positions"][0][0] = 0.3
        scene["particles"][0]["insert"]["velocities"] = [[slide, 0.0, 0.0]]
    with tempfile.TemporaryDirectory() as directory:
        sim = Simulation.from_dict(scene, output_dir=directory)
        level = LevelEnergy(sim)
        sim.step()  # the invariant needs the half-step velocities on both sides of a level: from t^1 on
        start = level.update()
        steps = int(round(end / sim.dt)) - 1
        lowest = highest = 0.0
        series = []
        started = time.perf_counter()
        for step in range(1, steps + 1):
            try:
                sim.step()
            except SolverError as error:
                series.append(f"stopped at {sim.time:.3f} s: {str(error).splitlines()[0]}")
                break
            change = level.update() - start
            lowest, highest = min(lowest, change), max(highest, change)
            if step % max(1, (steps + 1) // 5) == 0:
                series.append(f"{sim.time:.2f} s: {change:+.3g}")
        return dict(substeps=int(sim.coupling.fem_substeps["block"]), lowest=lowest, highest=highest,
                    bound=verlet_energy_bound(sim.dt), series=series, seconds=time.perf_counter() - started)


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    parser.add_argument("--cells", nargs="+", type=int, default=[4, 8, 16, 32])
    parser.add_argument("--element", default="P1", choices=["P1", "P2"])
    parser.add_argument("--modulus", type=float, default=1e6, help="the block's Young's modulus [Pa]")
    parser.add_argument("--restitution", type=float, default=1.0)
    parser.add_argument("--dt", type=float, default=2e-4)
    parser.add_argument("--end", type=float, default=1.0)
    parser.add_argument("--slide", type=float, default=0.0, help="initial sliding speed along x [m/s]")
    parser.add_argument("--transfer", default="nearest", choices=["nearest", "blended"], help="coupling.transfer")
    arguments = parser.parse_args()
    for cells in arguments.cells:
        result = run_case(cells, arguments.element, arguments.modulus, arguments.restitution, arguments.dt,
                          arguments.end, arguments.slide, arguments.transfer)
        print(f"{arguments.transfer} {arguments.element} {cells:>3} cells, E {arguments.modulus:g}, FE sub-steps {result['substeps']}: "
              f"energy change {result['lowest']:+.3g} .. {result['highest']:+.3g} J (Verlet bound "
              f"{result['bound']:.2g} J); {'; '.join(result['series'])} [{result['seconds']:.0f} s]", flush=True)


if __name__ == "__main__":
    main()

"""Stability map of the coupled scheme: a heavy sphere resting on a clamped steel block (tests/stability_cases.py).

For each case the sphere starts at rest at its Hertz overlap and the run lasts `--end` seconds (default 1 s,
about 8 periods of the resting contact).  Printed per case: FE sub-steps per DEM step, the largest nodal
speed in the block at the first and last sample, the largest growth of the total energy (particles + solid +
dissipated) over the run relative to m g delta (the contact's energy scale), and the sphere's overlap /
Hertz rest overlap at the end.  A stable case keeps the nodal speed from growing, the energy from rising, and
the overlap within 1 %.

    python benchmarks/coupled_stability.py                 # the map (several minutes)
    python benchmarks/coupled_stability.py --quick         # a few cases
Writes benchmarks/results/coupled_stability.json.
"""
from __future__ import annotations

import argparse
import json
import sys
import tempfile
from pathlib import Path

HERE = Path(__file__).resolve().parent
sys.path.insert(0, str(HERE.parent / "tests"))

import pdemfem  # noqa: E402,F401  (environment first)
from stability_cases import resting_scene, run_resting  # noqa: E402

from pdemfem.scene import derived  # noqa: E402
from pdemfem.scene.loader import load_scene  # noqa: E402


def allowed_step(scene: dict) -> float:
    """The DEM step `dt: auto` gives this scene."""
    automatic = dict(scene, time=dict(scene["time"], dt="auto"))
    loaded, _ = load_scene(automatic, base_dir=Path("."))
    return float(derived.time_step(loaded))


def cases(quick: bool):
    base = dict(cells=8, element="P1", mass="lumped", restitution=0.2, friction=0.0, dt_fraction=None, fem_every=1)
    chosen = []
    for cells in ((2, 4, 8, 16) if not quick else (4, 16)):
        chosen.append(dict(base, cells=cells))
    if quick:
        return chosen + [dict(base, cells=16, fem_every=5)]
    for element in ("P2",):
        chosen += [dict(base, cells=cells, element=element) for cells in (2, 4, 8)]
    chosen += [dict(base, cells=cells, mass="consistent") for cells in (4, 8)]
    chosen += [dict(base, cells=16, restitution=e) for e in (0.05, 0.5, 0.9)]
    chosen += [dict(base, cells=16, friction=0.5), dict(base, cells=16, friction=0.5, restitution=0.05)]
    chosen += [dict(base, cells=16, dt_fraction=f) for f in (0.1, 0.5, 1.0)]
    chosen += [dict(base, cells=16, fem_every=5), dict(base, cells=8, element="P2", fem_every=5, friction=0.5)]
    return chosen


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    parser.add_argument("--end", type=float, default=1.0)
    parser.add_argument("--quick", action="store_true")
    parser.add_argument("--dt", type=float, default=2e-4, help="DEM step of the cases without dt_fraction")
    arguments = parser.parse_args()
    rows = []
    header = (f"{'cells':>5} {'el':>2} {'mass':>10} {'e':>5} {'mu':>4} {'dt [s]':>9} {'k':>2} {'sub':>4} "
              f"{'v_node first':>12} {'v_node last':>12} {'max dE/(mg d)':>13} {'overlap':>8} {'wall s':>7}")
    print(header)
    for case in cases(arguments.quick):
        scene = resting_scene(case["cells"], element=case["element"], mass=case["mass"], restitution=case["restitution"],
                              friction=case["friction"], dt=arguments.dt, fem_every=case["fem_every"], end=arguments.end)
        if case["dt_fraction"] is not None:
            scene["time"]["dt"] = case["dt_fraction"] * allowed_step(scene)
        with tempfile.TemporaryDirectory() as directory:
            result = run_resting(scene, directory)
        growth = max(0.0, max(result["energy_change"])) / result["energy_scale"]
        row = dict(case, **result, energy_growth=growth)
        rows.append(row)
        print(f"{case['cells']:>5} {case['element']:>2} {case['mass']:>10} {case['restitution']:>5} {case['friction']:>4} "
              f"{result['dt']:>9.3g} {case['fem_every']:>2} {result['substeps']:>4} "
              f"{result['largest_nodal_speed'][0]:>12.3e} {result['largest_nodal_speed'][-1]:>12.3e} "
              f"{growth:>13.3e} {result['overlap_ratio'][-1]:>8.5f} {result['wall_seconds']:>7.1f}", flush=True)
    output = HERE / "results" / "coupled_stability.json"
    output.parent.mkdir(exist_ok=True)
    output.write_text(json.dumps(rows, indent=1))
    print(f"wrote {output}")


if __name__ == "__main__":
    main()

"""Angle of repose of 3-sphere clumps against single spheres (the figure of docs/shapes.md).

    python benchmarks/clump_repose.py [--count 150] [--end 0.4] [--rolling 0.1]

A heap in a slot: grains dropped from a region above the middle of a floor between two walls 6 mm
apart (y), free to spread along x.  Same material and contact law for both (linear spring k =
500 N/m, restitution 0.3, friction 0.5, and by default no rolling resistance: the spheres have
only sliding friction to hold a slope, the clumps their shape too; `--rolling` gives both the
constant-torque rolling resistance with that coefficient).  Spheres of radius 1 mm; clumps of three
spheres (1 mm, 0.8 mm, 0.7 mm, overlapping).  After `--end` seconds the heap's surface is taken
as the highest member top in bins one diameter wide along x, and each flank's slope is the least-
squares line through the bins between 20 % and 80 % of the heap's height; the angle is the mean
of the two flanks.  Written to benchmarks/results/clump_repose.json.
"""
from __future__ import annotations

import argparse
import json
import math
import time
from pathlib import Path

import numpy as np

from pdemfem import Simulation

ROOT = Path(__file__).resolve().parent.parent
DEFAULT_JSON = ROOT / "benchmarks" / "results" / "clump_repose.json"
RADIUS = 1e-3
SLOT = 6e-3
CLUMP = [{"position": [0, 0, 0], "radius": RADIUS}, {"position": [1.4 * RADIUS, 0, 0], "radius": 0.8 * RADIUS},
         {"position": [0.5 * RADIUS, 1.2 * RADIUS, 0.4 * RADIUS], "radius": 0.7 * RADIUS}]


def heap_scene(kind: str, count: int, end: float, folder: Path, rolling: float = 0.0) -> dict:
    group = {"name": kind, "material": "stone",
             "insert": {"kind": "random", "count": count, "seed": 11, "max_attempts": 20000,
                        "region": {"box": [[-0.01, -SLOT / 2, 0.004], [0.01, SLOT / 2, 0.1]]}}}
    if kind == "clumps":
        group["clump"] = {"spheres": CLUMP}
    else:
        group["radius"] = RADIUS
    walls = [{"name": "floor", "kind": "plane", "point": [0, 0, 0], "normal": [0, 0, 1], "material": "stone"},
             {"name": "front", "kind": "plane", "point": [0, -SLOT / 2, 0], "normal": [0, 1, 0], "material": "stone"},
             {"name": "back", "kind": "plane", "point": [0, SLOT / 2, 0], "normal": [0, -1, 0], "material": "stone"}]
    return {"time": {"end": end, "dt": "auto"}, "gravity": [0, 0, -9.81],
            "materials": {"stone": {"density": 2600, "youngs_modulus": 1e7, "poisson_ratio": 0.25}},
            "interactions": {"default": {"model": "linear_spring_dashpot", "normal_stiffness": 500.0,
                                         "restitution": 0.3, "friction": 0.5, "rolling_friction": rolling}},
            "particles": [group], "walls": walls,
            "output": {"dir": str(folder), "every": end, "particles": []}}


def repose_angle(positions, radii) -> tuple:
    """(angle in degrees, left, right, heap height) from the highest member top per bin along x."""
    tops = positions[:, 2] + radii
    width = 2.0 * RADIUS
    bins = np.floor(positions[:, 0] / width).astype(int)
    xs, heights = [], []
    for b in np.unique(bins):
        xs.append((b + 0.5) * width)
        heights.append(tops[bins == b].max())
    xs, heights = np.array(xs), np.array(heights)
    peak = heights.max()
    angles = []
    for side in (xs < xs[np.argmax(heights)], xs > xs[np.argmax(heights)]):
        chosen = side & (heights > 0.2 * peak) & (heights < 0.8 * peak)
        if chosen.sum() < 3:
            angles.append(float("nan"))
            continue
        slope = np.polyfit(xs[chosen], heights[chosen], 1)[0]
        angles.append(math.degrees(math.atan(abs(slope))))
    return float(np.nanmean(angles)), angles[0], angles[1], float(peak)


def main():
    parser = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    parser.add_argument("--count", type=int, default=150, help="clumps (and 3 x as many spheres)")
    parser.add_argument("--end", type=float, default=0.4)
    parser.add_argument("--rolling", type=float, default=0.0, help="rolling_friction of both")
    parser.add_argument("--json", type=Path, default=DEFAULT_JSON)
    arguments = parser.parse_args()
    results = {}
    for kind, count in (("spheres", 3 * arguments.count), ("clumps", arguments.count)):
        folder = Path("/tmp") / f"clump_repose_{kind}"
        start = time.perf_counter()
        sim = Simulation.from_dict(heap_scene(kind, count, arguments.end, folder, arguments.rolling), output_dir=folder,
                                   force=True)
        sim.run(progress=False)
        p = sim.particles
        energy = sim.energies()
        angle, left, right, height = repose_angle(p.positions, p.radii)
        results[kind] = {"count": count, "spheres": int(len(p.ids)), "angle_degrees": angle, "left": left,
                         "right": right, "height_m": height, "kinetic_energy": energy["kinetic_energy"],
                         "steps": sim.step_count, "seconds": time.perf_counter() - start}
        print(kind, json.dumps(results[kind]))
    arguments.json.parent.mkdir(parents=True, exist_ok=True)
    stored = json.loads(arguments.json.read_text()) if arguments.json.is_file() else {}
    stored[f"rolling_friction {arguments.rolling:g}"] = results
    arguments.json.write_text(json.dumps(stored, indent=2) + "\n")


if __name__ == "__main__":
    main()

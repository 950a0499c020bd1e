"""Candidate search for mesh walls: BVH vs brute force, cost per particle.

    .venv/bin/python benchmarks/bvh.py [--particles 2000] [--json benchmarks/results/bvh.json]

Surface: a wavy plate z = 0.02 sin(2 pi x) cos(2 pi y) over the unit square,
triangulated into 1e3, 1e4 and 1e5 triangles (a fine FE contact surface or a
detailed STL).  Particles: spheres of radius 5 mm (skin 1.5 mm, the default 0.3
radius) placed randomly within one radius above the surface, so that every one
has candidates -- the case that matters (particles resting on the wall).

Per size it reports: BVH build, refit (all vertices moved), candidate search
per particle with the BVH and with brute force (every triangle tested with the
same exact point-triangle distance), the speed-up, and the mean candidate list
length.  Brute force is timed on a subset of particles when it would take long.
Each timing is the best of `--repeat` runs after a warm-up (numba compiled).
"""
from __future__ import annotations

import argparse
import json
import platform
import time
from pathlib import Path

import numpy as np

from pdemfem.walls.bvh import BVH, brute_force_query

HERE = Path(__file__).resolve().parent
DEFAULT_JSON = HERE / "results" / "bvh.json"
RADIUS = 0.005
SKIN = 0.3 * RADIUS


def wavy_plate(triangle_target: int):
    cells = max(1, int(round(np.sqrt(triangle_target / 2.0))))
    x = np.linspace(0.0, 1.0, cells + 1)
    xx, yy = np.meshgrid(x, x, indexing="ij")
    zz = 0.02 * np.sin(2 * np.pi * xx) * np.cos(2 * np.pi * yy)
    vertices = np.column_stack([xx.ravel(), yy.ravel(), zz.ravel()])
    i, j = np.meshgrid(np.arange(cells), np.arange(cells), indexing="ij")
    a = (i * (cells + 1) + j).ravel()
    b = a + cells + 1
    triangles = np.concatenate([np.stack([a, b, b + 1], 1), np.stack([a, b + 1, a + 1], 1)]).astype(np.int32)
    return vertices, triangles


def particles_on(count: int, rng):
    x = rng.uniform(0.05, 0.95, count)
    y = rng.uniform(0.05, 0.95, count)
    z = 0.02 * np.sin(2 * np.pi * x) * np.cos(2 * np.pi * y) + rng.uniform(0.0, RADIUS, count)
    return np.column_stack([x, y, z])


def best_time(function, repeat: int) -> float:
    function()  # warm-up (compilation, caches)
    times = []
    for _ in range(repeat):
        start = time.perf_counter()
        function()
        times.append(time.perf_counter() - start)
    return min(times)


def measure(triangle_target: int, particle_count: int, repeat: int, brute_budget: float, rng) -> dict:
    vertices, triangles = wavy_plate(triangle_target)
    centers = particles_on(particle_count, rng)
    reach = np.full(particle_count, RADIUS + SKIN)
    build = best_time(lambda: BVH(vertices, triangles), repeat)
    bvh = BVH(vertices, triangles, rebuild_growth=np.inf)
    moved = vertices + rng.normal(0.0, 1e-4, vertices.shape)
    refit = best_time(lambda: bvh.refit(moved), repeat)
    bvh.refit(vertices)
    query = best_time(lambda: bvh.query(vertices, centers, reach), repeat)
    offsets, items = bvh.query(vertices, centers, reach)
    # Brute force on a subset small enough for the time budget (cost ~ 10 ns per triangle test).
    subset = int(min(particle_count, max(20, brute_budget / (len(triangles) * 10e-9))))
    brute = best_time(lambda: brute_force_query(vertices, triangles, centers[:subset], reach[:subset]), 1)
    reference = brute_force_query(vertices, triangles, centers[:subset], reach[:subset])
    assert np.array_equal(reference[0], offsets[:subset + 1]), "BVH and brute force disagree"
    return {
        "triangles": int(len(triangles)),
        "particles": particle_count,
        "build_ms": build * 1e3,
        "refit_ms": refit * 1e3,
        "bvh_us_per_particle": query / particle_count * 1e6,
        "brute_us_per_particle": brute / subset * 1e6,
        "brute_particles_timed": subset,
        "speedup": (brute / subset) / (query / particle_count),
        "mean_candidates": float(len(items) / particle_count),
        "bvh_nodes": int(bvh.node_total),
    }


def print_table(rows) -> None:
    print(f"{'triangles':>10} {'build ms':>9} {'refit ms':>9} {'BVH us/p':>9} {'brute us/p':>11} "
          f"{'speed-up':>9} {'cand/p':>7}")
    for row in rows:
        print(f"{row['triangles']:>10d} {row['build_ms']:>9.2f} {row['refit_ms']:>9.3f} "
              f"{row['bvh_us_per_particle']:>9.3f} {row['brute_us_per_particle']:>11.1f} "
              f"{row['speedup']:>9.0f} {row['mean_candidates']:>7.1f}")


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--particles", type=int, default=2000)
    parser.add_argument("--sizes", type=int, nargs="+", default=[1000, 10000, 100000])
    parser.add_argument("--repeat", type=int, default=5)
    parser.add_argument("--brute-budget", type=float, default=1.0, help="seconds of brute force per size")
    parser.add_argument("--json", type=Path, default=DEFAULT_JSON)
    args = parser.parse_args()
    rng = np.random.default_rng(0)
    rows = [measure(size, args.particles, args.repeat, args.brute_budget, rng) for size in args.sizes]
    print_table(rows)
    args.json.parent.mkdir(parents=True, exist_ok=True)
    result = {"benchmark": "bvh candidate search", "radius": RADIUS, "skin": SKIN,
              "machine": platform.machine(), "python": platform.python_version(), "rows": rows}
    args.json.write_text(json.dumps(result, indent=2) + "\n")
    print(f"written {args.json}")


if __name__ == "__main__":
    main()

"""Where the per-particle arrays start in a page, and what it costs the streaming kernels.

    .venv/bin/python benchmarks/memory_layout.py
    .venv/bin/python benchmarks/memory_layout.py --particles 14000 200000 1500000 --rounds 5

kick_drift walks eight per-particle arrays (positions, velocities, angular velocities, forces, torques,
positions at the list build, inverse mass and inertia) and writes four of them.  Arrays of more than
128 kB come from their own mmap, so malloc (numpy's np.empty) starts each of them 16 bytes into a page:
their addresses agree in the low 12 bits, a load then waits for any earlier store to the same page offset
("4K aliasing"), and the streams crowd the same L1 sets.  ParticleState starts each field's buffer at its
own offset (pdemfem.particles.state.staggered_empty, the golden-ratio sequence over a page's 64 cache lines).

Per size and round, alternating: kick_drift's time per particle (fastest tenth of the calls) on
  malloc's arrays   np.empty, as a fresh process lays them out (their page offsets printed)
  staggered         the same arrays at ParticleState's offsets for these fields
and the ratio of the two.  JSON goes to benchmarks/results/memory_layout.json (or --json PATH).
"""
from __future__ import annotations

import argparse
import json
import time
from pathlib import Path

import numpy as np

from pdemfem.particles.integrate import kick_drift
from pdemfem.particles.state import CORE_FIELD_SLOTS, staggered_empty

WALKED = ("positions", "velocities", "angular_velocities", "forces", "torques", "positions_at_build",
          "inverse_mass", "inverse_inertia")


def _arrays(count: int, allocate) -> dict:
    rng = np.random.default_rng(1)
    arrays = {}
    for name in WALKED:
        shape = (count,) if name.startswith("inverse") else (count, 3)
        arrays[name] = allocate(shape, CORE_FIELD_SLOTS[name])
        arrays[name][...] = rng.random(shape)
    return arrays


def _time_per_particle(arrays: dict, count: int) -> float:
    arguments = (count, arrays["positions"], arrays["velocities"], arrays["angular_velocities"], arrays["forces"],
                 arrays["torques"], arrays["inverse_mass"], arrays["inverse_inertia"], np.array([0.0, 0.0, -9.81]),
                 1.0e-5, 2.0e-5, arrays["positions_at_build"])
    kick_drift(*arguments)
    times = []
    for _ in range(max(20, 4_000_000 // count)):
        start = time.perf_counter()
        kick_drift(*arguments)
        times.append(time.perf_counter() - start)
    return float(np.percentile(times, 10)) / count


def main(argv=None):
    parser = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    parser.add_argument("--particles", type=int, nargs="+", default=[14000, 200000, 1500000])
    parser.add_argument("--rounds", type=int, default=3)
    parser.add_argument("--json", default=str(Path(__file__).parent / "results" / "memory_layout.json"))
    arguments = parser.parse_args(argv)
    layouts = {"malloc": lambda shape, slot: np.empty(shape),
               "staggered": lambda shape, slot: staggered_empty(shape, np.float64, slot)}
    rows = []
    print(f"{'particles':>9} {'round':>5} {'malloc ns/p':>12} {'staggered ns/p':>15} {'ratio':>6}  malloc's page offsets")
    for count in arguments.particles:
        for round_index in range(arguments.rounds):
            row = {"particles": count, "round": round_index}
            for layout, allocate in layouts.items():
                arrays = _arrays(count, allocate)
                row[f"{layout}_ns_per_particle"] = 1e9 * _time_per_particle(arrays, count)
                row[f"{layout}_page_offsets"] = [int(arrays[name].ctypes.data % 4096) for name in WALKED]
                del arrays
            row["ratio"] = row["malloc_ns_per_particle"] / row["staggered_ns_per_particle"]
            rows.append(row)
            print(f"{count:>9} {round_index:>5} {row['malloc_ns_per_particle']:>12.2f} "
                  f"{row['staggered_ns_per_particle']:>15.2f} {row['ratio']:>6.2f}  {row['malloc_page_offsets']}")
    Path(arguments.json).parent.mkdir(parents=True, exist_ok=True)
    Path(arguments.json).write_text(json.dumps({"benchmark": "memory_layout", "kernel": "kick_drift",
                                                "rows": rows}, indent=1))
    print(f"wrote {arguments.json}")


if __name__ == "__main__":
    main()

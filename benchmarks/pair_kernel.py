"""The pair kernel alone on the settle benchmark's bed: first evaluations set apart against computed in place.

    .venv/bin/python benchmarks/pair_kernel.py                      # bed at step 8000, 150 calls per round
    .venv/bin/python benchmarks/pair_kernel.py --steps 4000 --rounds 5

Runs the settle scene (benchmarks/settle.py) to --steps, then times the scene's compiled pair kernel
(pdemfem.contact.forces.pair_forces) on that state, the two ways alternating in one process, each call on a
fresh copy of the inputs (history and loads restored): with the set-apart buffer, as the particle system
calls it, and without it, where every contact is computed in place with the dashpot's onset factor inlined.
Prints best and median milliseconds per call for each round and writes them to JSON.
"""
from __future__ import annotations

import argparse
import json
import os
import sys
import tempfile
import time
from pathlib import Path

import numpy as np

sys.path.insert(0, str(Path(__file__).resolve().parent))
from settle import scene_dict  # noqa: E402


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    parser.add_argument("--particles", type=int, default=28000)
    parser.add_argument("--steps", type=int, default=8000, help="steps of the settle run before timing")
    parser.add_argument("--calls", type=int, default=150, help="calls per variant and round")
    parser.add_argument("--rounds", type=int, default=3)
    parser.add_argument("--json", default=str(Path(__file__).resolve().parent / "results" / "pair_kernel.json"))
    args = parser.parse_args()

    from pdemfem import Simulation

    simulation = Simulation.from_dict(scene_dict(args.particles),
                                      output_dir=os.path.join(tempfile.mkdtemp(prefix="pair-kernel-"), "out"))
    simulation.step(args.steps)
    system = simulation.particle_system
    state, neighbors, tables = system.state, system.neighbors, system.tables
    kernels = system.contact_kernels
    inputs = [neighbors.row_particles, neighbors.offsets[:-1], neighbors.offsets[1:], neighbors.partners,
              neighbors.history, state.ids, state.owned_count, state.positions, state.velocities,
              state.angular_velocities, state.radii, state.mass, state.inverse_inertia, state.material_index,
              tables.coefficients, tables.composition, system.dt, np.zeros_like(state.forces),
              np.zeros_like(state.torques), np.zeros(0), np.zeros((0, 2))]
    inputs = [value.copy() if isinstance(value, np.ndarray) else value for value in inputs]
    pristine = [value.copy() if isinstance(value, np.ndarray) else None for value in inputs]
    variants = {"set apart": [kernels.set_apart_buffer()], "in place": []}

    def timed_call(extra):
        for value, original in zip(inputs, pristine):
            if original is not None:
                value[...] = original
        start = time.perf_counter()
        totals = kernels.pair_forces(*inputs, *extra)
        return time.perf_counter() - start, totals

    results = {name: timed_call(extra)[1] for name, extra in variants.items()}  # compile both
    contacts = int(results["set apart"][2])
    rounds = []
    for round_index in range(args.rounds):
        row = {}
        for name, extra in variants.items():
            seconds = [timed_call(extra)[0] for _ in range(args.calls)]
            row[name] = {"best_ms": 1e3 * min(seconds), "median_ms": 1e3 * float(np.median(seconds))}
        rounds.append(row)
        print(f"round {round_index + 1}: " + "   ".join(
            f"{name}: best {value['best_ms']:.3f} ms, median {value['median_ms']:.3f} ms" for name, value in row.items()),
            flush=True)
    listed = int(neighbors.offsets[-1])
    print(f"bed at step {simulation.step_count}: {listed:,} listed pairs, {contacts:,} contacts")
    for name in variants:
        best = min(row[name]["best_ms"] for row in rounds)
        print(f"  {name:10s} best {best:.3f} ms  = {1e6 * best / max(contacts, 1):.1f} ns per contact")
    Path(args.json).parent.mkdir(parents=True, exist_ok=True)
    Path(args.json).write_text(json.dumps({"benchmark": "pair_kernel", "step": simulation.step_count,
                                           "listed_pairs": listed, "contacts": contacts, "rounds": rounds}, indent=1))
    print(f"results: {args.json}")


if __name__ == "__main__":
    main()

"""How much of p cores this machine delivers when p of them compute at once.

    python benchmarks/core_capacity.py --cores 2 --rounds 10

A register-bound loop (no memory traffic) is timed on each core alone, then on all p cores at once, the two
alternating round by round so that both see the same spell of the machine.  Per round

    capacity = sum over the cores of (time alone / time together)

is p on dedicated cores and less where the cores share something the loop needs: a physical core (SMT
siblings) or the host's time (a virtual machine on an overcommitted host, whose virtual cores each ran at full
speed alone).  A p-rank run cannot be faster than T(1) / capacity for work this loop stands for, so
benchmarks/scaling.py prints the capacity beside the parallel efficiency (docs/parallel.md).
"""
from __future__ import annotations

import argparse
import json
import multiprocessing
import os
import time

import numpy as np
from numba import njit

LOOP_ITERATIONS = 20_000_000  # ~40 ms on one Zen 4 core


@njit(cache=True)
def _register_loop(iterations):
    total = 0.0
    for i in range(iterations):
        total += (i % 7) * 0.5 ** (i % 5)
    return total


def _timed_loop(core, start, results, slot):
    if core is not None:
        os.sched_setaffinity(0, {core})
    start.wait()
    began = time.perf_counter()
    _register_loop(LOOP_ITERATIONS)
    results[slot] = time.perf_counter() - began


def _run(cores_at_once, pin: bool) -> list:
    """Time one loop on each of `cores_at_once` (one process each, started together)."""
    context = multiprocessing.get_context("fork")
    results = context.Array("d", len(cores_at_once))
    start = context.Barrier(len(cores_at_once))
    processes = [context.Process(target=_timed_loop, args=(core if pin else None, start, results, slot))
                 for slot, core in enumerate(cores_at_once)]
    for process in processes:
        process.start()
    for process in processes:
        process.join()
    return list(results)


def core_capacity(cores: int, rounds: int = 8) -> dict:
    """Alone and together loop times per core and round, and the capacity per round and its median.  The
    loops are pinned to cores 0 .. cores-1 where this process may use them (else the OS places them)."""
    _register_loop(10)  # compile (or load from the cache) before forking
    pin = hasattr(os, "sched_getaffinity") and set(range(cores)) <= os.sched_getaffinity(0)
    alone = np.zeros((rounds, cores))
    together = np.zeros((rounds, cores))
    for round_index in range(rounds):
        for core in range(cores):
            alone[round_index, core] = _run([core], pin)[0]
        together[round_index] = _run(list(range(cores)), pin)
    capacity = (alone / together).sum(axis=1)
    return {"cores": cores, "pinned": pin, "alone_seconds": alone.tolist(), "together_seconds": together.tolist(),
            "capacity_of_rounds": capacity.tolist(), "capacity": float(np.median(capacity))}


def main(argv=None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--cores", type=int, default=2)
    parser.add_argument("--rounds", type=int, default=8)
    parser.add_argument("--json", default=None, help="write the figures here too")
    args = parser.parse_args(argv)
    result = core_capacity(args.cores, args.rounds)
    alone = np.array(result["alone_seconds"])
    together = np.array(result["together_seconds"])
    print(f"register loop, {args.cores} cores{' (pinned)' if result['pinned'] else ''}, {args.rounds} rounds")
    print(f"{'round':>5} " + " ".join(f"{'alone ' + str(c) + ' ms':>11} {'together ' + str(c):>11}"
                                       for c in range(args.cores)) + f" {'capacity':>9}")
    for round_index in range(args.rounds):
        print(f"{round_index:>5} " + " ".join(f"{1e3 * alone[round_index, c]:>11.1f} {1e3 * together[round_index, c]:>11.1f}"
                                              for c in range(args.cores))
              + f" {result['capacity_of_rounds'][round_index]:>9.2f}")
    print(f"capacity (median of the rounds): {result['capacity']:.2f} of {args.cores} cores")
    if args.json:
        with open(args.json, "w") as handle:
            json.dump(result, handle, indent=1)
    return 0


if __name__ == "__main__":
    raise SystemExit(main())

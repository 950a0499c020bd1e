"""Figures of docs/shapes.md: rigid-body step conservation and cost, mass-property and fill accuracy.

    python benchmarks/clump_integrator.py [--bodies 10000] [--steps 200]

Printed (and written to benchmarks/results/clump_integrator.json):

* free asymmetric body (I = 1, 2, 3.5), 1e5 steps at omega dt = 0.01 and 0.02: change of the world
  angular momentum, largest |E - E0| / E0, and the drift of the mean energy (last tenth - first tenth);
* intermediate-axis flip period and axisymmetric precession rate errors at two steps (order);
* cost of one rigid-body step (kick, drift, kick) per body for --bodies bodies;
* ray-grid mass properties: error against the exact two-sphere union for n = 32 ... 1024 and the time
  per call;
* sphere fill of a 2 x 1 x 1 box and a 1 x 0.6 x 0.4 ellipsoid: coverage against the number of spheres.
"""
from __future__ import annotations

import argparse
import json
import math
import sys
import time
from pathlib import Path

import numpy as np

ROOT = Path(__file__).resolve().parent.parent
sys.path.insert(0, str(ROOT / "tests"))

from test_clumps_fill import box_mesh, ellipsoid_mesh  # noqa: E402
from test_clumps_rigid_body import _body, _body_momentum, _energy, _precession, flip_period  # noqa: E402

from pdemfem.clumps.fill import fill_surface  # noqa: E402
from pdemfem.clumps.quaternion import quaternion_from_axis_angle  # noqa: E402
from pdemfem.clumps.rigid_body import drift_bodies, kick_bodies  # noqa: E402
from pdemfem.clumps.shape import exact_union_moments, ray_grid_moments  # noqa: E402

DEFAULT_JSON = ROOT / "benchmarks" / "results" / "clump_integrator.json"


def free_body(omega_dt, steps=100_000):
    x, v, q, momenta, moments = _body((1.0, 2.0, 3.5), [0.8, -1.1, 0.6], quaternion_from_axis_angle([1, 2, 3], 0.7))
    omega = float(np.linalg.norm(_body_momentum(q, momenta) / moments[0]))
    dt = omega_dt / omega
    start = momenta.copy()
    e0 = _energy(q, momenta, moments)
    energies = []
    zero = np.zeros((1, 3))
    for n in range(steps):
        kick_bodies(1, v, momenta, zero, zero, np.ones(1), np.zeros(3), 0.5 * dt)
        drift_bodies(1, x, v, q, momenta, moments, dt)
        kick_bodies(1, v, momenta, zero, zero, np.ones(1), np.zeros(3), 0.5 * dt)
        if n % 10 == 0:
            energies.append(_energy(q, momenta, moments))
    energies = np.array(energies)
    tenth = len(energies) // 10
    return {"omega_dt": omega_dt, "momentum_change": float(np.abs(momenta - start).max()),
            "energy_oscillation": float(np.abs(energies - e0).max() / e0),
            "energy_drift": float((energies[-tenth:].mean() - energies[:tenth].mean()) / e0)}


def flip(dt):
    x, v, q, momenta, moments = _body((1.0, 2.0, 3.0), [0.02, 1.0, 0.02])
    period = flip_period((1.0, 2.0, 3.0), float(momenta[0] @ momenta[0]), _energy(q, momenta, moments))
    crossings, previous, t = [], _body_momentum(q, momenta)[1], 0.0
    for _ in range(int(3.2 * period / dt)):
        drift_bodies(1, x, v, q, momenta, moments, dt)
        t += dt
        current = _body_momentum(q, momenta)[1]
        if previous * current < 0:
            crossings.append(t - dt * current / (current - previous))
        previous = current
    return {"dt": dt, "period": period, "relative_error": 2 * float(np.mean(np.diff(crossings))) / period - 1}


def step_cost(bodies, steps):
    rng = np.random.default_rng(1)
    x, v = rng.normal(size=(bodies, 3)), rng.normal(size=(bodies, 3))
    q = np.array([quaternion_from_axis_angle(rng.normal(size=3), rng.uniform(0, 3)) for _ in range(bodies)])
    momenta, moments = rng.normal(size=(bodies, 3)), rng.uniform(1, 2, size=(bodies, 3))
    forces, torques, inverse_mass = rng.normal(size=(bodies, 3)), rng.normal(size=(bodies, 3)), np.ones(bodies)
    gravity = np.array([0, 0, -9.81])
    best = math.inf
    for _ in range(3):
        start = time.perf_counter()
        for _ in range(steps):
            kick_bodies(bodies, v, momenta, forces, torques, inverse_mass, gravity, 5e-7)
            drift_bodies(bodies, x, v, q, momenta, moments, 1e-6)
            kick_bodies(bodies, v, momenta, forces, torques, inverse_mass, gravity, 5e-7)
        best = min(best, (time.perf_counter() - start) / (steps * bodies))
    return best


def ray_grid_errors():
    centers, radii = np.array([[0.0, 0, 0], [1.3, 0.4, -0.2]]), np.array([1.0, 0.7])

    def central(volume, first, second):
        c = first / volume
        s = second - volume * np.outer(c, c)
        return volume, np.trace(s) * np.eye(3) - s
    exact_volume, exact_inertia = central(*exact_union_moments(centers, radii))
    rows = []
    for n in (32, 64, 128, 256, 512, 1024):
        start = time.perf_counter()
        volume, inertia = central(*ray_grid_moments(centers, radii, n))
        elapsed = time.perf_counter() - start
        rows.append({"n": n, "mass_error": abs(volume / exact_volume - 1),
                     "inertia_error": float(np.abs(inertia - exact_inertia).max() / np.abs(exact_inertia).max()),
                     "seconds": elapsed})
    return rows


def fills():
    out = {}
    for name, (vertices, triangles) in {"box 2x1x1": box_mesh([0, 0, 0], [2, 1, 1]),
                                        "ellipsoid 1x0.6x0.4": ellipsoid_mesh((1.0, 0.6, 0.4))}.items():
        rows = []
        for count in (1, 2, 4, 8, 16, 32, 64):
            start = time.perf_counter()
            fill = fill_surface(vertices, triangles, count)
            rows.append({"spheres": len(fill.radii), "coverage": fill.coverage,
                         "seconds": time.perf_counter() - start})
        out[name] = rows
    return out


def main(argv=None):
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--bodies", type=int, default=10000)
    parser.add_argument("--steps", type=int, default=200)
    parser.add_argument("--json", type=Path, default=DEFAULT_JSON)
    args = parser.parse_args(argv)
    fill_surface(*box_mesh([0, 0, 0], [1, 1, 1]), 2)   # compile outside the timings
    ray_grid_moments(np.zeros((1, 3)), np.ones(1), 8)
    result = {
        "free_body": [free_body(0.01), free_body(0.02)],
        "flip": [flip(0.02), flip(0.01)],
        "precession": [dict(zip(("dt", "body_error", "axis_error"),
                                (dt, *(lambda r: (r[0] / r[1] - 1, r[2] / r[3] - 1))(_precession(dt, 60.0)))))
                       for dt in (0.02, 0.01)],
        "step_seconds_per_body": step_cost(args.bodies, args.steps),
        "ray_grid": ray_grid_errors(),
        "fill": fills(),
    }
    print(json.dumps(result, indent=1))
    args.json.parent.mkdir(parents=True, exist_ok=True)
    args.json.write_text(json.dumps(result, indent=1) + "\n")


if __name__ == "__main__":
    main()

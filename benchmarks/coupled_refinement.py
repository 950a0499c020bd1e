"""Coupled contact under mesh refinement: a sphere hitting a clamped block, against independent references.

The sphere of the ball-on-block case (R = 0.2 m, density 10000, E = 1e7, nu = 0.2, restitution 0.2,
frictionless) hits the top centre of a 1 x 1 x 0.5 m block clamped at its base at 2.4 m/s.  The block is
meshed with n x n x n/2 cubes (n = 2 .. 16, each cube 6 tetrahedra), P1 or P2, lumped mass, and the
particle-solid contact modulus is `combined` (E* holds both bodies' compliance) or `particle` (the
particle's only; the FE mesh supplies the block's deformation).  Two blocks:

  stiff  steel, E = 2e10 (2000x the sphere).  Reference: the rigid-plane limit -- the damped Hertz
         impact of the sphere on an immovable half-space with E* of the pair (the contact law integrated
         as an ODE, `damped_hertz_impact`; without gravity its rebound is the analytic e v); the same
         sphere on a plane wall is run too (it must equal the ODE to the time-integration error).
  soft   the sphere's own material (E = 1e7, nu = 0.2; density 1000 so that the block's elastic waves
         cross it ~10x within the contact and the block responds quasi-statically, as a half-space under
         Hertz's assumptions).  Reference: two-body Hertz with damping -- the damped Hertz impact with
         E* = E / (2 (1 - nu^2)) (both bodies' compliance), m* = the sphere's mass (the block is
         clamped), R* = R.  The reference quantities are the contact duration and the peak contact force,
         which measure the contact's stiffness (they scale as E*^(-2/5) and E*^(2/5)).  The rebound is
         printed too but is no reference on a deformable block: the contact's dashpot damps only the
         contact's share of the deformation, the FE's elastic share returns its energy (docs/coupling.md).

Per case only a short window around the impact is simulated: the sphere starts 1 mm above the top and
the run stops `FREE_STEPS` force-free steps after the pulse (measure_impact / against_reference define the
rebound, the duration and the filtered peak force compared with the reference).

    python benchmarks/coupled_refinement.py                      # full table (~2-3 min, 1 rank)
    python benchmarks/coupled_refinement.py --cells 2 4 --elements P1
    python benchmarks/coupled_refinement.py --plot docs/img/coupled_refinement.png --markdown
    python benchmarks/coupled_refinement.py --blocks soft --restitution 1.0 \
        --json benchmarks/results/coupled_refinement_elastic.json   # the elastic (e = 1) table

Prints a table and writes benchmarks/results/coupled_refinement.json.  docs/coupling.md
("Contact modulus of a deformable solid") explains the results.
"""
from __future__ import annotations

import argparse
import json
import math
import tempfile
import time
from pathlib import Path

import pdemfem  # noqa: F401  (environment first)

from pdemfem import Simulation
from pdemfem.contact.restitution import normal_damping_coefficient
from pdemfem.errors import SolverError

HERE = Path(__file__).resolve().parent
DEFAULT_JSON = HERE / "results" / "coupled_refinement.json"

GRAVITY = 0.0         # no gravity: the reference restitution is then exact (and a soft contact lasts long
                      # enough for gravity to eat the whole rebound at e = 0.2)
RADIUS = 0.2
SPHERE = {"density": 10000.0, "youngs_modulus": 1e7, "poisson_ratio": 0.2}
BLOCKS = {
    "stiff": {"density": 7850.0, "youngs_modulus": 2e10, "poisson_ratio": 0.29},
    "soft": {"density": 1000.0, "youngs_modulus": 1e7, "poisson_ratio": 0.2},
}
RESTITUTION = 0.2
SPEED = 2.4           # impact speed [m/s] (the sphere starts GAP above the top)
GAP = 1e-3
TOP = 0.5             # block 1 x 1 x 0.5 m, clamped at z = 0
DT = 1e-5             # DEM step: 5e-6 changes rebound and duration by < 0.1 % (soft 8x8x4); only the soft block's
                      # 16x16x8 at e = 0.2 (past the point-load limit, ringing) moves, by 2 % / 7 % (combined / particle)
FREE_STEPS = 20       # force-free steps that end a pulse (a ringing surface may interrupt it briefly)
WIDTH_LEVEL = 0.05    # the pulse duration is its width at this fraction of the reference peak force
PEAK_WINDOW = 0.02    # peak force = the largest mean over this fraction of the reference pulse (filters the
                      # ringing of the loaded FE node, a mesh mode far above the pulse; the sampled peak is kept)


def sphere_mass() -> float:
    return 4.0 / 3.0 * math.pi * RADIUS**3 * SPHERE["density"]


def effective_modulus(block: dict, modulus: str) -> float:
    """E* of sphere-block contacts: both compliances (combined) or the sphere's (particle)."""
    compliance = (1 - SPHERE["poisson_ratio"] ** 2) / SPHERE["youngs_modulus"]
    if modulus == "combined":
        compliance += (1 - block["poisson_ratio"] ** 2) / block["youngs_modulus"]
    return 1.0 / compliance


def scene(block: str, element: str = "P1", cells: int = 2, modulus: str = "combined", dt: float = DT,
          rigid_plane: bool = False, restitution: float = RESTITUTION, transfer: str = "nearest") -> dict:
    """The impact scene: a clamped n x n x n/2 block (or, rigid_plane, a plane wall at its top)."""
    start = TOP + RADIUS + GAP
    data = {
        "time": {"end": 1.0, "dt": dt},
        "gravity": [0.0, 0.0, -GRAVITY],
        "materials": {"sphere": dict(SPHERE), "block": dict(BLOCKS[block])},
        "interactions": {"default": {"model": "hertz_mindlin", "restitution": restitution, "friction": 0.0}},
        "particles": [{"name": "ball", "material": "sphere", "radius": RADIUS,
                       "insert": {"kind": "list", "positions": [[0.5, 0.5, start]],
                                  "velocities": [[0.0, 0.0, -math.sqrt(SPEED**2 - 2 * GRAVITY * GAP)]]}}],
        "coupling": {"fem_every": 1, "contact_modulus": modulus, "transfer": transfer},
        "output": {"particles": [], "solids": []},
    }
    if rigid_plane:
        data["walls"] = [{"name": "block", "kind": "plane", "point": [0, 0, TOP], "normal": [0, 0, 1],
                          "material": "block"}]
    else:
        data["solids"] = [{"name": "block", "mesh": {"box": [[0, 0, 0], [1, 1, TOP]],
                                                     "cells": [cells, cells, max(1, cells // 2)]},
                           "material": "block", "element": element, "mass": "lumped", "fixed": ["zmin"],
                           "contact": ["zmax"]}]
    return data


def impact_time() -> float:
    """When the sphere (starting GAP above the top, see scene) touches the undeformed top."""
    start_speed = math.sqrt(SPEED**2 - 2 * GRAVITY * GAP)
    return GAP / start_speed if GRAVITY == 0.0 else (SPEED - start_speed) / GRAVITY


def pulse_width(times, forces, level: float) -> float:
    """Time between the first upward and the last downward crossing of `level` (linear interpolation)."""
    above = [k for k, force in enumerate(forces) if force >= level]
    first, last = above[0], above[-1]

    def crossing(k0, k1):
        return times[k0] + (level - forces[k0]) / (forces[k1] - forces[k0]) * (times[k1] - times[k0])

    return crossing(last, last + 1) - crossing(first - 1, first)


def measure_impact(data: dict, output_dir: str, window: float = 0.3) -> dict:
    """Run the impact and sample the contact force every step until FREE_STEPS force-free steps follow it.

    rebound: the sphere's free-flight invariant w = v + g t taken after the pulse, as the velocity at the
      reference's separation time: w - g (t_impact + t_ref).  It is the momentum the contact gave the
      sphere, independent of where a weak ringing tail of the pulse ends (a block's ringing surface
      switches the nearly zero clamped force on and off for a few steps at the end).
    duration: the force-pulse width at WIDTH_LEVEL of the reference peak force (interpolated).
    sampled_peak_force: the largest sampled force (peak_force, filtered, see against_reference).  block_indentation:
    the largest downward top displacement; surface_speed: the largest vertical top-node speed."""
    sim = Simulation.from_dict(data, output_dir=output_dir)
    dt = sim.dt
    started = time.perf_counter()
    solid = sim.solids.get("block")
    if solid is not None:
        top_nodes = solid.group_node_numbers("zmax")
        settled_top = solid.displacements[top_nodes, 2].copy()   # the static sag under the block's own weight
    times, forces, free, deepest, surface_speed, touched = [0.0], [0.0], 0, 0.0, 0.0, False
    for _ in range(int(window / dt)):
        sim.step()
        force = abs(float(sim.wall_force("block")[2]))
        times.append(sim.time)
        forces.append(force)
        touched = touched or force > 0.0
        free = free + 1 if touched and force == 0.0 else 0
        if solid is not None and touched:
            deepest = max(deepest, float(-(solid.displacements[top_nodes, 2] - settled_top).min()))
            surface_speed = max(surface_speed, float(abs(solid.velocities[top_nodes, 2]).max()))
        if free == FREE_STEPS:
            break
    else:
        raise RuntimeError(f"the sphere did not rebound within {window} s")
    invariant = float(sim.particles.velocities[0, 2]) + GRAVITY * sim.time
    if invariant <= 0.0:
        raise RuntimeError(f"the sphere passed through the surface after a {max(forces):.3g} N pulse (tunnelled)")
    return {"invariant": invariant, "forces": forces, "times": times, "sampled_peak_force": max(forces),
            "block_indentation": deepest, "surface_speed": surface_speed, "fem_substeps": sim.coupling.fem_substeps.get("block", 0), "dt": dt,
            "seconds": time.perf_counter() - started}


def against_reference(measured: dict, ref: dict) -> dict:
    """The measured rebound and pulse width in the reference's terms (see measure_impact)."""
    rebound = measured["invariant"] - GRAVITY * (impact_time() + ref["separation"])
    width = pulse_width(measured["times"], measured["forces"], WIDTH_LEVEL * ref["peak_force"])
    result = {key: value for key, value in measured.items() if key not in ("forces", "times", "invariant")}
    window = max(1, round(PEAK_WINDOW * ref["duration"] / measured["dt"]))
    forces = measured["forces"]
    smoothed = max((sum(forces[k:k + window]) / window for k in range(len(forces) - window + 1)),
                   default=measured["sampled_peak_force"])
    result.update(rebound=rebound, duration=width, peak_force=smoothed)
    return result


def damped_hertz_impact(e_star: float, mass: float = None, radius: float = RADIUS, speed: float = SPEED,
                        restitution: float = RESTITUTION, gravity: float = GRAVITY, step: float = 2e-6) -> dict:
    """The kernel's clamped damped Hertz law (pdemfem.contact.restitution) for a sphere on an immovable
    half-space, with gravity: m d'' = -max(0, k d^1.5 + gamma sqrt(m S_n) d') + m g, k = 4/3 E* sqrt(R),
    S_n = 1.5 k sqrt(d), d(0) = 0, d'(0) = speed.  Returns the rebound speed (-d' when the clamped force
    first vanishes: the sphere then flies freely), the separation time, the peak force, the largest
    overlap and the pulse
    duration (width at WIDTH_LEVEL of the peak, as measured in the simulations).  RK4, h = `step`
    (~1/30000 of the pulse: error ~1e-10 relative), the end interpolated linearly between steps."""
    mass = sphere_mass() if mass is None else mass
    k = 4.0 / 3.0 * e_star * math.sqrt(radius)
    gamma = normal_damping_coefficient("hertz_mindlin", restitution)
    damping = gamma * math.sqrt(mass * 1.5 * k)

    def force(d, v):
        d = max(d, 0.0)
        return k * d**1.5 + damping * d**0.25 * v

    def accel(d, v):
        return -max(0.0, force(d, v)) / mass + gravity

    t, d, v, previous, deepest = 0.0, 0.0, speed, 0.0, 0.0
    times, forces = [0.0], [0.0]
    while True:
        k1d, k1v = v, accel(d, v)
        k2d, k2v = v + 0.5 * step * k1v, accel(d + 0.5 * step * k1d, v + 0.5 * step * k1v)
        k3d, k3v = v + 0.5 * step * k2v, accel(d + 0.5 * step * k2d, v + 0.5 * step * k2v)
        k4d, k4v = v + step * k3v, accel(d + step * k3d, v + step * k3v)
        new_d = d + step / 6 * (k1d + 2 * k2d + 2 * k3d + k4d)
        new_v = v + step / 6 * (k1v + 2 * k2v + 2 * k3v + k4v)
        f = force(new_d, new_v)
        if v < 0.0 and (f <= 0.0 or new_d <= 0.0):
            fraction = previous / (previous - f) if f <= 0.0 < previous else 1.0
            times.append(t + fraction * step)
            forces.append(0.0)
            peak = max(forces)
            return {"rebound": -(v + fraction * (new_v - v)), "separation": times[-1], "peak_force": peak,
                    "max_overlap": deepest,
                    "duration": pulse_width(times, forces, WIDTH_LEVEL * peak)}
        t, d, v, previous = t + step, new_d, new_v, f
        deepest = max(deepest, d)
        times.append(t)
        forces.append(f)


def reference(block: str, restitution: float = RESTITUTION) -> dict:
    """The independent reference of a block: the damped Hertz impact with E* of both bodies."""
    return damped_hertz_impact(effective_modulus(BLOCKS[block], "combined"), restitution=restitution)


def run(blocks, elements, cells_list, moduli, dt=DT, restitution=RESTITUTION, log=print, transfer="nearest") -> dict:
    results = {"dt": dt, "speed": SPEED, "restitution": restitution, "transfer": transfer, "sphere": SPHERE,
               "radius": RADIUS,
               "blocks": {name: BLOCKS[name] for name in blocks}, "cases": []}
    with tempfile.TemporaryDirectory() as scratch:
        for block in blocks:
            ref = reference(block, restitution)
            results.setdefault("references", {})[block] = ref
            log(f"{block} block: reference (damped Hertz, E* = {effective_modulus(BLOCKS[block], 'combined'):.4g}) "
                f"rebound {ref['rebound']:.4f} m/s, duration {ref['duration'] * 1e3:.3f} ms, peak {ref['peak_force']:.5g} N")
            plane = against_reference(measure_impact(scene(block, dt=dt, rigid_plane=True, restitution=restitution), scratch), ref)
            results["cases"].append(dict(block=block, element="plane", cells=0, modulus="combined", **plane))
            log(_row(block, "plane", 0, "combined", plane, ref))
            for element in elements:
                for modulus in moduli:
                    for cells in cells_list:
                        try:
                            measured = against_reference(measure_impact(
                                scene(block, element, cells, modulus, dt=dt, restitution=restitution, transfer=transfer), scratch),
                                ref)
                        except (SolverError, RuntimeError) as error:   # a case that blows up is a result too
                            results["cases"].append(dict(block=block, element=element, cells=cells, modulus=modulus,
                                                         failed=str(error).splitlines()[0]))
                            log(f"{block:5s} {element:5s} {cells}x{cells}x{max(1, cells // 2)} {modulus:8s} FAILED: "
                                f"{str(error).splitlines()[0]}")
                            continue
                        results["cases"].append(dict(block=block, element=element, cells=cells, modulus=modulus,
                                                     **measured))
                        log(_row(block, element, cells, modulus, measured, ref))
    return results


def _row(block, element, cells, modulus, measured, ref) -> str:
    mesh = f"{cells}x{cells}x{max(1, cells // 2)}" if cells else "-"
    return (f"{block:5s} {element:5s} {mesh:8s} {modulus:8s} rebound {measured['rebound']:.4f} "
            f"({measured['rebound'] / ref['rebound'] - 1:+7.2%})  duration {measured['duration'] * 1e3:7.3f} ms "
            f"({measured['duration'] / ref['duration'] - 1:+7.2%})  peak {measured['peak_force']:9.4g} N "
            f"({measured['peak_force'] / ref['peak_force'] - 1:+7.2%})  indentation {measured['block_indentation']:.2e} m"
            f"  sub-steps {measured['fem_substeps']}  dt {measured['dt']:.0e}  {measured['seconds']:.1f} s")


def markdown(results: dict) -> str:
    """The table of docs/coupling.md: value and deviation from the reference per case."""
    lines = ["| block | element | cells | modulus | rebound [m/s] | duration [ms] | peak force [kN] | FE indentation u [mm] |",
             "|---|---|---|---|---|---|---|---|"]
    for block, ref in results["references"].items():
        lines.append(f"| {block} | reference | — | — | {ref['rebound']:.3f} | {ref['duration'] * 1e3:.2f} | "
                     f"{ref['peak_force'] / 1e3:.2f} | (δ_max = {ref['max_overlap'] * 1e3:.1f}) |")
        for case in results["cases"]:
            if case["block"] != block:
                continue
            mesh = f"{case['cells']}×{case['cells']}×{max(1, case['cells'] // 2)}" if case["cells"] else "plane wall"
            if "failed" in case:
                lines.append(f"| {block} | {case['element']} | {mesh} | {case['modulus']} | failed: {case['failed']} | | | |")
                continue
            lines.append(
                f"| {block} | {case['element']} | {mesh} | {case['modulus']} | {case['rebound']:.3f} "
                f"({case['rebound'] / ref['rebound'] - 1:+.1%}) | {case['duration'] * 1e3:.2f} "
                f"({case['duration'] / ref['duration'] - 1:+.1%}) | {case['peak_force'] / 1e3:.2f} "
                f"({case['peak_force'] / ref['peak_force'] - 1:+.1%}) | {case['block_indentation'] * 1e3:.3g} |")
    return "\n".join(lines)


def plot(results: dict, path: Path) -> None:
    from pdemfem.plot import agg_pyplot

    plt = agg_pyplot()

    quantities = (("rebound", "rebound / reference"), ("duration", "duration / reference"),
                  ("peak_force", "peak force / reference"))
    blocks = list(results["references"])
    figure, axes = plt.subplots(len(blocks), 3, figsize=(12, 3.2 * len(blocks)), squeeze=False)
    for row, block in enumerate(blocks):
        ref = results["references"][block]
        for column, (key, label) in enumerate(quantities):
            axis = axes[row][column]
            for element, marker in (("P1", "o"), ("P2", "s")):
                for modulus, style in (("combined", "-"), ("particle", "--")):
                    cases = [c for c in results["cases"] if c["block"] == block and c["element"] == element
                             and c["modulus"] == modulus and "failed" not in c]
                    if cases:
                        axis.plot([c["cells"] for c in cases], [c[key] / ref[key] for c in cases], style,
                                  marker=marker, label=f"{element} {modulus}")
            axis.axhline(1.0, color="k", lw=0.8)
            axis.set_xscale("log", base=2)
            axis.set_xlabel("cells per side")
            axis.set_ylabel(label)
            axis.set_title(f"{block} block")
            if row == 0 and column == 0:
                axis.legend(fontsize=8)
    figure.tight_layout()
    path.parent.mkdir(parents=True, exist_ok=True)
    figure.savefig(path, dpi=90)


def main(argv=None) -> None:
    parser = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    parser.add_argument("--blocks", nargs="+", default=list(BLOCKS), choices=list(BLOCKS))
    parser.add_argument("--elements", nargs="+", default=["P1", "P2"], choices=["P1", "P2"])
    parser.add_argument("--cells", nargs="+", type=int, default=[2, 4, 8, 16], help="cells per side (n x n x n/2)")
    parser.add_argument("--moduli", nargs="+", default=["combined", "particle"], choices=["combined", "particle"])
    parser.add_argument("--dt", type=float, default=DT)
    parser.add_argument("--restitution", type=float, default=RESTITUTION)
    parser.add_argument("--transfer", default="nearest", choices=["nearest", "blended"],
                        help="coupling.transfer of the block cases (docs/coupling.md)")
    parser.add_argument("--json", type=Path, default=DEFAULT_JSON)
    parser.add_argument("--plot", type=Path, default=None, help="also draw the table (PNG)")
    parser.add_argument("--markdown", action="store_true", help="also print the table as markdown")
    args = parser.parse_args(argv)
    results = run(args.blocks, args.elements, args.cells, args.moduli, dt=args.dt, restitution=args.restitution,
                  log=lambda line: print(line, flush=True), transfer=args.transfer)
    args.json.parent.mkdir(parents=True, exist_ok=True)
    args.json.write_text(json.dumps(results, indent=1))
    print(f"wrote {args.json}")
    if args.markdown:
        print(markdown(results))
    if args.plot:
        plot(results, args.plot)
        print(f"wrote {args.plot}")


if __name__ == "__main__":
    main()

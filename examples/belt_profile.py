"""Deflection along the belt of examples/belt.yaml at the end of a run, against a beam estimate.

    python examples/belt_profile.py out/belt [--scene examples/belt.yaml] [--png docs/img/belt_profile.png]

Reads the run's last output step: the belt's nodal displacements (belt.h5), the gravel's positions and
radii (particles.h5), and history.csv (mass_in - mass_out: the gravel in the scene; the idlers'
reaction columns), with the belt's geometry, material and idlers from the scene.

Estimate: the belt as a beam on three idlers at x = 0, L, 2L (two equal spans, pinned supports), each
span i under a uniform load q_i = belt weight per length + (gravel mass above span i) g / L.  The
three-moment equation gives the hogging moment over the middle idler, M = (q_1 + q_2) L^2 / 16, and then
span 1 (x from the tail idler; span 2 mirrored from the head idler):

    w(x) = q_1 x (L^3 - 2 L x^2 + x^3) / (24 EI) - M x (L^2 - x^2) / (6 EI L)
    R_tail = q_1 L / 2 - M / L,  R_head = q_2 L / 2 - M / L,  R_mid = (q_1 + q_2) L / 2 + 2 M / L.

(q_1 = q_2 = q: mid-span w = q L^4 / (192 EI), idler loads 3/8, 10/8, 3/8 q L.)
EI: the beam value E b t^3 / 12 and the plate (cylindrical bending) value E b t^3 / (12 (1 - nu^2))
bound the belt (8 cm wide over 30 cm spans); the estimate is drawn as the band between the two.
The gravel's weight is taken as spread evenly over each span and as static (its impacts and its
acceleration by the belt are left out).
"""
from __future__ import annotations

import argparse
from pathlib import Path

import numpy as np


def hogging_moment(span, load_1, load_2):
    """Moment over the middle idler of two equal pinned spans (three-moment equation) [N m]."""
    return (load_1 + load_2) * span ** 2 / 16.0


def span_deflection(x, span, load, moment, bending_stiffness):
    """Downward w(x) of a span pinned at x = 0 with the hogging moment `moment` at x = span."""
    return (load * x * (span ** 3 - 2.0 * span * x ** 2 + x ** 3) / 24.0
            - moment * x * (span ** 2 - x ** 2) / (6.0 * span)) / bending_stiffness


def two_span_deflection(x, span, load_1, load_2, bending_stiffness):
    moment = hogging_moment(span, load_1, load_2)
    return np.where(x <= span, span_deflection(x, span, load_1, moment, bending_stiffness),
                    span_deflection(2.0 * span - x, span, load_2, moment, bending_stiffness))


def idler_loads(span, load_1, load_2):
    moment = hogging_moment(span, load_1, load_2)
    return (load_1 * span / 2 - moment / span, (load_1 + load_2) * span / 2 + 2 * moment / span,
            load_2 * span / 2 - moment / span)


def read_steps(run, solid_name):
    import h5py

    with h5py.File(run / f"{solid_name}.h5", "r") as handle:
        points = handle["mesh/points"][...]
        steps = sorted(name for name in handle if name.startswith("step_"))
        first, last = handle[steps[0]], handle[steps[-1]]
        belt = (points, first["displacements"][...], last["displacements"][...],
                float(first.attrs["time"]), float(last.attrs["time"]))
    with h5py.File(run / "particles.h5", "r") as handle:
        last = handle[sorted(name for name in handle if name.startswith("step_"))[-1]]
        grains = (last["positions"][...], last["radii"][...], float(last.attrs["time"]))
    return belt, grains


def main(argv=None):
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("run", type=Path, help="the run's output directory (pdemfem run ... -o DIR)")
    parser.add_argument("--scene", type=Path, default=Path(__file__).with_name("belt.yaml"))
    parser.add_argument("--png", type=Path, default=None, help="write the figure here")
    args = parser.parse_args(argv)

    from pdemfem.plot import read_history
    from pdemfem.scene.loader import load_scene

    scene, _ = load_scene(args.scene)
    solid = scene.solids[0]
    material = scene.materials[solid.material]
    grain_density = scene.materials[scene.particles[0].material].density
    (points, u_start, u_end, t_start, t_end), (positions, radii, t_grains) = read_steps(args.run, solid.name)
    # The belt's extent from its mesh (a box however it was meshed: meshes/belt.geo or a mesh: {box} entry).
    (x0, y0, z0), (x1, y1, z1) = points.min(axis=0), points.max(axis=0)
    idlers = sorted(region.cylinder.point[0] for region in solid.regions.values())
    span = idlers[1] - idlers[0]
    if len(idlers) != 3 or abs((idlers[2] - idlers[1]) - span) > 1e-9 * span:
        raise SystemExit("the estimate is for three idlers at equal spacing")
    width, thickness, length = y1 - y0, z1 - z0, x1 - x0
    gravity = abs(scene.gravity[2])
    beam_stiffness = material.youngs_modulus * width * thickness ** 3 / 12.0
    plate_stiffness = beam_stiffness / (1.0 - material.poisson_ratio ** 2)

    masses = grain_density * 4.0 / 3.0 * np.pi * radii ** 3
    on_span = [np.sum(masses[(positions[:, 0] >= a) & (positions[:, 0] < b)])
               for a, b in ((idlers[0], idlers[1]), (idlers[1], idlers[2]))]
    belt_load = material.density * width * thickness * gravity
    load_1, load_2 = (belt_load + mass * gravity / span for mass in on_span)

    history = read_history(args.run / "history.csv")
    in_scene = float(history["mass_in"][-1] - history["mass_out"][-1])
    reactions = [float(history[f"reaction_{solid.name}_{name}_z"][-1]) for name in solid.regions]
    # The last third of the run (steady loading): time means smooth out the impacts and the belt's ringing.
    steady = history["time"] >= history["time"][-1] * 2.0 / 3.0
    mean_reactions = [float(np.mean(history[f"reaction_{solid.name}_{name}_z"][steady])) for name in solid.regions]
    mean_gravel = float(np.mean((history["mass_in"] - history["mass_out"])[steady]))

    top_centre = (np.abs(points[:, 1] - 0.5 * (y0 + y1)) < 1e-9) & (np.abs(points[:, 2] - z1) < 1e-9)
    order = np.argsort(points[top_centre, 0])
    x = points[top_centre, 0][order]
    sag_end = -u_end[top_centre, 2][order]
    sag_start = -u_start[top_centre, 2][order]
    mid = np.array([idlers[0] + 0.5 * span, idlers[1] + 0.5 * span])
    measured = np.interp(mid, x, sag_end)
    plate = two_span_deflection(mid, span, load_1, load_2, plate_stiffness)
    beam = two_span_deflection(mid, span, load_1, load_2, beam_stiffness)
    print(f"t = {t_end:.3f} s (grains {t_grains:.3f} s): gravel on the spans {on_span[0] * 1e3:.1f} g, "
          f"{on_span[1] * 1e3:.1f} g (in the scene {in_scene * 1e3:.1f} g); belt {belt_load:.3f} N/m, "
          f"q = {load_1:.3f}, {load_2:.3f} N/m")
    for k, name in enumerate(("tail", "head")):
        print(f"{name} span mid-span sag: measured {measured[k] * 1e3:.3f} mm, estimate {plate[k] * 1e3:.3f} "
              f"(plate EI) .. {beam[k] * 1e3:.3f} mm (beam EI); measured / beam estimate {measured[k] / beam[k]:.3f}")
    estimate = idler_loads(span, load_1, load_2)
    print("idler loads [N] (" + ", ".join(solid.regions) + "): at the end " + ", ".join(f"{value:.3f}" for value in reactions)
          + " (sum %.3f); mean over the last third " % sum(reactions)
          + ", ".join(f"{value:.3f}" for value in mean_reactions) + " (sum %.3f); estimate " % sum(mean_reactions)
          + ", ".join(f"{value:.3f}" for value in estimate) + " (sum %.3f)" % sum(estimate))
    print(f"weight: belt {belt_load * length:.3f} N + gravel {mean_gravel * gravity:.3f} N (mean mass_in - mass_out "
          f"over the last third) = {belt_load * length + mean_gravel * gravity:.3f} N")

    if args.png is not None:
        import matplotlib

        matplotlib.use("Agg")
        import matplotlib.pyplot as plt

        dense = np.linspace(idlers[0], idlers[2], 401)
        figure, axes = plt.subplots(figsize=(7.0, 3.6))
        axes.fill_between(dense, -1e3 * two_span_deflection(dense, span, load_1, load_2, beam_stiffness),
                          -1e3 * two_span_deflection(dense, span, load_1, load_2, plate_stiffness),
                          color="tab:orange", alpha=0.35, label="beam estimate, belt + gravel (EI beam .. plate)")
        axes.plot(dense, -1e3 * two_span_deflection(dense, span, belt_load, belt_load, plate_stiffness),
                  color="tab:gray", ls="--", lw=1, label="estimate, belt only (plate EI)")
        axes.plot(x, -1e3 * sag_start, "o", ms=3, color="tab:gray", label=f"FE, t = {t_start:.2f} s (no gravel)")
        axes.plot(x, -1e3 * sag_end, "o-", ms=3, color="tab:blue",
                  label=f"FE, t = {t_end:.2f} s ({sum(on_span) * 1e3:.0f} g gravel on the belt)")
        axes.plot(idlers, [0.0] * 3, "^", color="k", ms=8)
        axes.set_xlabel("x along the belt [m]")
        axes.set_ylabel("deflection, top centre line [mm]")
        axes.set_ylim(None, 0.9)
        axes.set_title("Belt deflection on three idlers (examples/belt.yaml)")
        axes.legend(fontsize=7, loc="upper center", ncol=2)
        figure.tight_layout()
        args.png.parent.mkdir(parents=True, exist_ok=True)
        figure.savefig(args.png, dpi=120)
        print(f"wrote {args.png}")


if __name__ == "__main__":
    main()

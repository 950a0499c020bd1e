"""Hopper discharge: measured discharge rate against Beverloo, and the wall stress against Janssen.

The scene is examples/hopper_discharge.yaml: a flat-bottomed rectangular bin (B = 60 mm wide along x,
L = 30 mm deep along y, plane walls at y = 0 and y = L) with a slot orifice of width b across the whole
depth L, centred at x = B/2; the x = 0 side is an elastic panel (a clamped FE solid), the x = B side is a
stack of horizontal mesh-wall strips (wall_strip_0 at the bottom ... wall_strip_8 at the top), each of
which reports its own force (history force_<strip>_x), so the wall's normal stress is known per height.

Two kinds of run, both from that scene file:

* closed: the orifice plugged by a plane wall at z = 0 (`plug`), the grains settle to rest; the last
  rows' strip forces give the wall normal stress vs depth (Janssen) and the last particle output the
  bulk density rho_b (the volume of the spheres whose centres lie in a horizontal slab of the bin,
  over the slab's volume);
* open, at each slot width b: the bin discharges; mass_out(t) (grains crossing the outlet plane 30 mm
  below the orifice) is fitted by a straight line over its steady part, the slope is the rate W.

References (constants stated as used):

* Beverloo, Leniger & van de Velde, Chem. Eng. Sci. 15 (1961) 260: W = C rho_b sqrt(g) (D - k d)^(5/2)
  for a circular orifice, C = 0.58, k = 1.4 (1.3-1.5 in the data they fit).
* Nedderman, Statics and Kinematics of Granular Materials (1992), ch. 10: the slot form
  W = C' rho_b sqrt(g) (L - k d)(b - k d)^(3/2), C' = 1.03, k = 1.4 (Myers & Sellers' slot data).  Here
  the slot spans the bin's whole depth L between two walls: (L - k d) is that depth's effective
  length, as in the slot correlation.
* Janssen (1895): sigma_w(z) = rho_b g D_h / (4 mu_w) (1 - exp(-4 mu_w K z / D_h)), z the depth below
  the free surface, D_h = 4 A / P the hydraulic diameter of the bin's section (A = B L, P = 2 (B + L)),
  mu_w the grain-wall friction, K the ratio of horizontal to vertical stress: Jaky's K = 1 - sin(phi)
  with phi = atan(mu) the friction angle of the grain contacts is stated, and the K that fits the
  measured profile best is reported beside it.

    python benchmarks/hopper_discharge.py --ranks 1       # b = 16, 20, 24 mm: the figures of docs/applications_hopper.md
    python benchmarks/hopper_discharge.py --slots 0.016 0.024 --end 0.35 --ranks 1
    python benchmarks/hopper_discharge.py --plots docs/img  # hopper_beverloo.png, hopper_janssen.png

Results: benchmarks/results/hopper_discharge.json (or --json).
"""
from __future__ import annotations

import argparse
import json
import math
import os
import subprocess
import sys
import tempfile
import time
from pathlib import Path

import numpy as np
import yaml

HERE = Path(__file__).resolve().parent
REPOSITORY = HERE.parent
SCENE = REPOSITORY / "examples" / "hopper_discharge.yaml"
MESHES = REPOSITORY / "examples" / "meshes"
DEFAULT_JSON = HERE / "results" / "hopper_discharge.json"

# Geometry of the bin (m): keep in step with examples/hopper_discharge.yaml (written by write_example_meshes).
BIN_WIDTH = 0.06          # B, along x
BIN_DEPTH = 0.03          # L, along y
WALL_HEIGHT = 0.13        # the side walls reach this high
STRIP_HEIGHT = 0.01       # the measured wall's strips below STRIP_TOP
STRIP_TOP = 0.08          # above it one tall strip closes the wall
EXAMPLE_SLOT = 0.02       # the example's slot width b
GRAVITY = 9.81

BEVERLOO_CIRCULAR_C = 0.58
BEVERLOO_SLOT_C = 1.03
BEVERLOO_K = 1.4


# ------------------------------------------------------------------------------------------ geometry
def _geo_number(value: float) -> str:
    return f"{value:.12g}"


def _write_rectangles_geo(path: Path, description: str, rectangles) -> None:
    """A gmsh .geo file of flat rectangles (corner, edge_u, edge_v), each meshed as two triangles (a
    transfinite surface with one cell: a flat wall needs no more); each rectangle's normal is u x v."""
    lines = [f"// {line}" for line in description.splitlines()]
    lines += ["// Written by benchmarks/hopper_discharge.py (write_example_meshes); pdemfem meshes it when a scene",
              "// names it (walls[].file).  To look at it: gmsh " + path.name + " -2"]
    for index, (corner, edge_u, edge_v) in enumerate(rectangles):
        p0 = np.asarray(corner, float)
        corners = (p0, p0 + edge_u, p0 + edge_u + edge_v, p0 + edge_v)
        first_point, first_line = 4 * index + 1, 4 * index + 1
        for k, point in enumerate(corners):
            lines.append(f"Point({first_point + k}) = {{{', '.join(_geo_number(c) for c in point)}}};")
        for k in range(4):
            lines.append(f"Line({first_line + k}) = {{{first_point + k}, {first_point + (k + 1) % 4}}};")
        loop = ", ".join(str(first_line + k) for k in range(4))
        lines.append(f"Curve Loop({index + 1}) = {{{loop}}};")
        lines.append(f"Plane Surface({index + 1}) = {{{index + 1}}};")
        lines.append(f"Transfinite Curve{{{loop}}} = 2;")
        lines.append(f"Transfinite Surface{{{index + 1}}};")
    path.write_text("\n".join(lines) + "\n")


def slot_bottom_rectangles(slot_width: float):
    """The bin's floor at z = 0: two plates leaving a slot of width b across the depth, centred at B/2
    (normal +z: into the bin)."""
    half = 0.5 * (BIN_WIDTH - slot_width)
    if half <= 0:
        raise ValueError(f"slot width {slot_width} must be smaller than the bin width {BIN_WIDTH}")
    return [((0, 0, 0), np.array([half, 0, 0]), np.array([0, BIN_DEPTH, 0])),
            ((BIN_WIDTH - half, 0, 0), np.array([half, 0, 0]), np.array([0, BIN_DEPTH, 0]))]


def write_slot_bottom(path: Path, slot_width: float) -> None:
    """The floor with a slot of width b as a gmsh .geo file (slot_bottom_rectangles)."""
    _write_rectangles_geo(path, f"The hopper's floor at z = 0: two plates leaving a {slot_width * 1000:g} mm slot "
                                f"across the bin's depth,\ncentred at x = {BIN_WIDTH / 2 * 1000:g} mm.",
                          slot_bottom_rectangles(slot_width))


def strip_bounds():
    """(z_low, z_high) of each strip of the measured wall, bottom to top."""
    count = int(round(STRIP_TOP / STRIP_HEIGHT))
    bounds = [(k * STRIP_HEIGHT, (k + 1) * STRIP_HEIGHT) for k in range(count)]
    bounds.append((STRIP_TOP, WALL_HEIGHT))
    return bounds


def write_strips(folder: Path):
    """The x = B wall as separate flat strips (one .geo file each, normal +x); returns their file names,
    bottom to top."""
    names = []
    for index, (low, high) in enumerate(strip_bounds()):
        name = f"hopper_strip_{index}.geo"
        rectangle = ((BIN_WIDTH, 0, low), np.array([0, BIN_DEPTH, 0]), np.array([0, 0, high - low]))
        _write_rectangles_geo(folder / name, f"Strip {index} of the hopper's measured wall at x = "
                                             f"{BIN_WIDTH * 1000:g} mm: z = {low * 1000:g} .. {high * 1000:g} mm.",
                              [rectangle])
        names.append(name)
    return names


def write_example_meshes(folder: Path = MESHES) -> None:
    """The mesh (.geo) files of examples/hopper_discharge.yaml's walls (run once; they are committed):
        python -c "import sys; sys.path.insert(0, 'benchmarks'); import hopper_discharge as h; h.write_example_meshes()"
    The panel's mesh, hopper_panel.geo, is written by hand."""
    write_slot_bottom(folder / "hopper_bottom.geo", EXAMPLE_SLOT)
    write_strips(folder)


# ------------------------------------------------------------------------------------------ correlations
def beverloo_slot(bulk_density: float, slot_width: float, diameter: float, depth: float = BIN_DEPTH,
                  c: float = BEVERLOO_SLOT_C, k: float = BEVERLOO_K, gravity: float = GRAVITY) -> float:
    """Nedderman's slot form of Beverloo's correlation (kg/s)."""
    return c * bulk_density * math.sqrt(gravity) * (depth - k * diameter) * (slot_width - k * diameter) ** 1.5


def beverloo_circular(bulk_density: float, orifice_diameter: float, diameter: float,
                      c: float = BEVERLOO_CIRCULAR_C, k: float = BEVERLOO_K, gravity: float = GRAVITY) -> float:
    """Beverloo, Leniger & van de Velde (1961), circular orifice (kg/s)."""
    return c * bulk_density * math.sqrt(gravity) * (orifice_diameter - k * diameter) ** 2.5


def hydraulic_diameter(width: float = BIN_WIDTH, depth: float = BIN_DEPTH) -> float:
    return 4.0 * width * depth / (2.0 * (width + depth))


def janssen_wall_stress(depth, bulk_density: float, wall_friction: float, k_ratio: float,
                        hydraulic: float, gravity: float = GRAVITY):
    """Janssen's wall normal stress at depth z below the free surface (Pa)."""
    depth = np.asarray(depth, dtype=float)
    scale = bulk_density * gravity * hydraulic / (4.0 * wall_friction)
    return scale * (1.0 - np.exp(-4.0 * wall_friction * k_ratio * depth / hydraulic))


def janssen_floor_share(height: float, wall_friction: float, k_ratio: float, hydraulic: float) -> float:
    """Share of a column's weight that Janssen's vertical stress leaves on the floor under a fill of `height`:
    sigma_v(H) A / (rho_b g H A) = (D_h / (4 mu_w K H)) (1 - exp(-4 mu_w K H / D_h))."""
    x = 4.0 * wall_friction * k_ratio * height / hydraulic
    return (1.0 - math.exp(-x)) / x


def k_from_floor_share(share: float, height: float, wall_friction: float, hydraulic: float) -> float:
    """The K for which Janssen's floor share equals the measured one (it falls with K: bisection)."""
    low, high = 1e-4, 20.0
    for _ in range(100):
        middle = 0.5 * (low + high)
        if janssen_floor_share(height, wall_friction, middle, hydraulic) > share:
            low = middle
        else:
            high = middle
    return 0.5 * (low + high)


def fit_janssen_k(depth, stress, bulk_density, wall_friction, hydraulic) -> float:
    """The K that minimises the squared misfit of Janssen's profile to the measured stresses (golden section)."""
    def misfit(k_ratio):
        return float(np.sum((janssen_wall_stress(depth, bulk_density, wall_friction, k_ratio, hydraulic)
                             - stress) ** 2))
    low, high = 0.01, 3.0
    ratio = (math.sqrt(5) - 1) / 2
    for _ in range(80):
        a, b = high - ratio * (high - low), low + ratio * (high - low)
        if misfit(a) < misfit(b):
            high = b
        else:
            low = a
    return 0.5 * (low + high)


# ------------------------------------------------------------------------------------------ reading outputs
def read_history(path: Path):
    from pdemfem.plot import read_history as _read
    return _read(path)


def steady_rate(time, mass_out, start: float, stop: float):
    """Slope of mass_out(t) over [start, stop] (least squares) and the largest residual over the mass
    that left in that window (how far from linear the discharge was)."""
    mask = (time >= start) & (time <= stop)
    if mask.sum() < 3:
        raise ValueError(f"fewer than 3 history rows in the fit window [{start}, {stop}] s")
    slope, intercept = np.polyfit(time[mask], mass_out[mask], 1)
    residual = mass_out[mask] - (slope * time[mask] + intercept)
    passed = mass_out[mask][-1] - mass_out[mask][0]
    return float(slope), float(np.abs(residual).max() / passed) if passed > 0 else float("inf")


def last_particles(path: Path):
    """Positions and radii of the last step in particles.h5."""
    import h5py
    with h5py.File(path, "r") as handle:
        steps = sorted(key for key in handle if key.startswith("step_"))
        group = handle[steps[-1]]
        return np.asarray(group["positions"]), np.asarray(group["radii"])


def bulk_density_in_slab(positions, radii, density: float, z_low: float, z_high: float,
                         width: float = BIN_WIDTH, depth: float = BIN_DEPTH) -> float:
    """Mass of the spheres whose centre lies in z_low <= z < z_high inside the bin, over the slab volume
    (unbiased for a slab much thicker than a grain: spheres cut by its faces count in or out on average)."""
    inside = ((positions[:, 2] >= z_low) & (positions[:, 2] < z_high) & (positions[:, 0] > 0)
              & (positions[:, 0] < width))
    mass = density * (4.0 / 3.0) * math.pi * float(np.sum(radii[inside] ** 3))
    return mass / (width * depth * (z_high - z_low))


def free_surface_height(positions, radii, width: float = BIN_WIDTH, depth: float = BIN_DEPTH) -> float:
    """Height of the free surface: the bed's sphere volume spread over the section at the bed's packing
    fraction measured in its lower half (so a rough top counts at its mean height)."""
    inside = (positions[:, 0] > 0) & (positions[:, 0] < width) & (positions[:, 2] > 0)
    top = float(np.max(positions[inside, 2]))
    volume = (4.0 / 3.0) * math.pi * radii[inside] ** 3
    lower = inside & (positions[:, 2] < 0.5 * top)
    fraction = float(np.sum((4.0 / 3.0) * math.pi * radii[lower] ** 3)) / (width * depth * 0.5 * top)
    return float(np.sum(volume)) / (fraction * width * depth)


def wall_stress_profile(history, since: float):
    """Mean normal stress on each strip (Pa) over the history rows from time `since` on (each row already
    averages the steps since the previous one), with the strip's centre height.  The strips lie at x = B with
    the grains on their -x side: the grains push them along +x."""
    rows = history["time"] >= since
    centres, stresses = [], []
    for index, (low, high) in enumerate(strip_bounds()):
        column = f"mean_force_wall_strip_{index}_x"
        force = float(np.mean(history[column][rows]))
        centres.append(0.5 * (low + high))
        stresses.append(force / (BIN_DEPTH * (high - low)))
    return np.array(centres), np.array(stresses)


# ------------------------------------------------------------------------------------------ scenes
def scene_dict(slot_width: float | None, end: float, mesh_folder: Path, output_every: float,
               particles: bool = False, floor_speed: float = 0.0) -> dict:
    """The example scene with its floor's slot set to slot_width; None: a closed bin, whose floor is a plane
    `plug` at z = 0 (the slotted floor removed) moving down at floor_speed [m/s]."""
    data = yaml.safe_load(SCENE.read_text())
    data["time"]["end"] = end
    for wall in data["walls"]:
        if wall.get("kind") == "mesh":
            wall["file"] = str((SCENE.parent / wall["file"]).resolve())
    for solid in data.get("solids", []):
        if isinstance(solid.get("mesh"), str):
            solid["mesh"] = str((SCENE.parent / solid["mesh"]).resolve())
    bottom = next(wall for wall in data["walls"] if wall["name"] == "bottom")
    if slot_width is None:
        data["walls"].remove(bottom)
        data["walls"].append({"name": "plug", "kind": "plane", "point": [0, 0, 0], "normal": [0, 0, 1],
                              "material": bottom["material"], "velocity": [0, 0, -floor_speed]})
    else:
        path = mesh_folder / f"hopper_bottom_{slot_width * 1000:.1f}mm.geo"
        write_slot_bottom(path, slot_width)
        bottom["file"] = str(path)
    data["output"] = {"dir": "out", "every": output_every,
                      "particles": ["positions", "radii"] if particles else [], "solids": []}
    return data


def closed_bin(settle: float, floor_speed: float, folder: Path, ranks: int, density: float,
               wall_friction: float, grain_friction: float) -> dict:
    """Fill the closed bin, let it settle for `settle` s with its floor moving down at floor_speed; the wall
    stress profile against Janssen, the bulk density, the share of the weight the floor carries."""
    started = time.perf_counter()
    output = run_scene(scene_dict(None, settle, folder, output_every=0.01, particles=True, floor_speed=floor_speed),
                       folder, ranks)
    history = read_history(output / "history.csv")
    positions, radii = last_particles(output / "particles.h5")
    surface = free_surface_height(positions, radii)
    bulk_density = bulk_density_in_slab(positions, radii, density, 0.1 * surface, 0.8 * surface)
    weight = density * (4.0 / 3.0) * math.pi * float(np.sum(radii ** 3)) * GRAVITY
    # Averages over the second half of the run: the bed has settled (kinetic energy ~1e-6 J) and the
    # force chains' fluctuation (a strip holds ~20 grain contacts) averages out over many rows.
    since = 0.5 * settle
    floor_share = -float(np.mean(history["mean_force_plug_z"][history["time"] >= since])) / weight
    centres, stresses = wall_stress_profile(history, since)
    below = centres < surface
    depths = surface - centres[below]
    measured = stresses[below]
    hydraulic = hydraulic_diameter()
    phi = math.atan(grain_friction)
    k_jaky = 1.0 - math.sin(phi)
    k_fit = fit_janssen_k(depths, measured, bulk_density, wall_friction, hydraulic)
    janssen = janssen_wall_stress(depths, bulk_density, wall_friction, k_jaky, hydraulic)
    hydrostatic = k_jaky * bulk_density * GRAVITY * depths
    k_floor = k_from_floor_share(floor_share, surface, wall_friction, hydraulic) if floor_share < 1 else float("nan")
    # K measured directly at the floor: the lowest strip's normal stress over the floor's mean vertical stress.
    k_direct = stresses[0] / (floor_share * bulk_density * GRAVITY * surface)
    janssen_direct = janssen_wall_stress(depths, bulk_density, wall_friction, k_direct, hydraulic)
    result = {
        "seconds": time.perf_counter() - started, "settle_time": settle, "floor_speed": floor_speed,
        "kinetic_energy_end": float(history["kinetic_energy"][-1]), "floor_share_of_weight": floor_share,
        "free_surface": surface, "bulk_density": bulk_density, "packing_fraction": bulk_density / density,
        "hydraulic_diameter": hydraulic, "k_jaky": k_jaky, "phi_deg": math.degrees(phi), "k_fit": k_fit,
        "k_from_floor_share": k_floor, "k_direct": k_direct,
        "floor_share_janssen_k_jaky": janssen_floor_share(surface, wall_friction, k_jaky, hydraulic),
        "rows": [{"depth": float(z), "height": float(h), "stress": float(s), "janssen": float(j),
                  "ratio": float(s / j), "hydrostatic_k_jaky": float(p),
                  "janssen_k_direct": float(jd), "ratio_k_direct": float(s / jd)}
                 for z, h, s, j, p, jd in zip(depths, centres[below], measured, janssen, hydrostatic, janssen_direct)],
    }
    print(f"closed bin, floor moving down at {floor_speed * 1000:.1f} mm/s: free surface {surface * 1000:.1f} mm, "
          f"rho_b {bulk_density:.0f} kg/m^3 (packing {bulk_density / density:.3f}), floor carries "
          f"{floor_share:.2f} of the weight, K Jaky {k_jaky:.3f} (phi = atan(mu) = {math.degrees(phi):.1f} deg), "
          f"(Janssen with it: {janssen_floor_share(surface, wall_friction, k_jaky, hydraulic):.2f}), "
          f"K fitted to the wall stresses {k_fit:.3f}, K from the floor share {k_floor:.3f}, "
          f"K = sigma_w / sigma_v at the floor {k_direct:.3f}, kinetic energy at the end {history['kinetic_energy'][-1]:.2e} J")
    print(f"{'depth mm':>9} {'sigma_w Pa':>11} {'Janssen Pa':>11} {'ratio':>6} {'Janssen(K direct)':>17} "
          f"{'ratio':>6} {'K rho g z Pa':>12}")
    for row in result["rows"]:
        print(f"{row['depth'] * 1000:9.1f} {row['stress']:11.1f} {row['janssen']:11.1f} {row['ratio']:6.2f} "
              f"{row['janssen_k_direct']:17.1f} {row['ratio_k_direct']:6.2f} {row['hydrostatic_k_jaky']:12.1f}")
    return result


def run_scene(data: dict, folder: Path, ranks: int) -> Path:
    folder.mkdir(parents=True, exist_ok=True)
    scene = folder / "scene.yaml"
    scene.write_text(yaml.safe_dump(data, sort_keys=False))
    output = folder / "out"
    command = [sys.executable, "-m", "pdemfem.launch", "-n", str(ranks), "--", sys.executable, "-m", "pdemfem.cli",
               "run", str(scene), "-o", str(output), "--quiet", "--force"]
    subprocess.run(command, check=True, env=dict(os.environ))
    return output


def main(argv=None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    parser.add_argument("--slots", type=float, nargs="*", default=[0.016, 0.02, 0.024], help="slot widths b [m]")
    parser.add_argument("--end", type=float, default=0.4, help="discharge run length [s]")
    parser.add_argument("--fit", type=float, nargs=2, default=[0.15, 0.35], help="steady window [s] of the fit")
    parser.add_argument("--settle", type=float, default=0.5, help="closed-bin run length [s]")
    parser.add_argument("--floor-speeds", type=float, nargs="+", default=[0.0, 0.005],
                        help="closed bin: the floor sinks at these speeds [m/s] (0: at rest; the first gives rho_b)")
    parser.add_argument("--ranks", type=int, default=2)
    parser.add_argument("--json", type=Path, default=DEFAULT_JSON)
    parser.add_argument("--plots", type=Path, default=None, help="folder for hopper_beverloo.png, hopper_janssen.png")
    parser.add_argument("--work", type=Path, default=None, help="folder for the runs (default: a temporary one)")
    args = parser.parse_args(argv)

    scene = yaml.safe_load(SCENE.read_text())
    group = scene["particles"][0]
    density = float(scene["materials"][group["material"]]["density"])
    diameter = float(group["radius"]["min"] + group["radius"]["max"])   # mean diameter: 2 x mean radius
    wall_friction = float(scene["interactions"]["grain-steel"]["friction"])
    grain_friction = float(scene["interactions"]["default"]["friction"])

    work = args.work or Path(tempfile.mkdtemp(prefix="hopper_discharge_"))
    work.mkdir(parents=True, exist_ok=True)
    results = {"scene": str(SCENE.relative_to(REPOSITORY)), "ranks": args.ranks, "diameter": diameter,
               "bin_width": BIN_WIDTH, "bin_depth": BIN_DEPTH, "wall_friction": wall_friction,
               "grain_friction": grain_friction}

    # Closed bin: at rest (the bulk density for Beverloo), and with its floor sinking (Janssen).
    results["closed"] = [closed_bin(args.settle, speed, work / f"closed_{speed * 1000:.1f}", args.ranks, density,
                                    wall_friction, grain_friction) for speed in args.floor_speeds]
    bulk_density = results["closed"][0]["bulk_density"]

    # Open bin at each slot width: the discharge rate.
    rows = []
    if not args.slots:
        args.slots = []
    for slot in args.slots:
        started = time.perf_counter()
        output = run_scene(scene_dict(slot, args.end, work, output_every=0.005), work / f"slot_{slot * 1000:.1f}",
                           args.ranks)
        history = read_history(output / "history.csv")
        rate, nonlinearity = steady_rate(history["time"], history["mass_out"], *args.fit)
        predicted = beverloo_slot(bulk_density, slot, diameter)
        rows.append({"slot": slot, "slot_over_d": slot / diameter, "rate": rate, "beverloo": predicted,
                     "ratio": rate / predicted, "nonlinearity": nonlinearity,
                     "mass_out_end": float(history["mass_out"][-1]),
                     "mass_in_bin_end": float(history["particles"][-1]), "seconds": time.perf_counter() - started,
                     "time": history["time"].tolist(), "mass_out": history["mass_out"].tolist()})
    results["discharge"] = {"fit_window": args.fit, "c_slot": BEVERLOO_SLOT_C, "k": BEVERLOO_K, "rows": rows}
    if len(rows) >= 2:
        # W / (L - k d) ~ (b - k d)^n: the exponent from the measured rates, with Beverloo's k.
        x = np.log([row["slot"] - BEVERLOO_K * diameter for row in rows])
        y = np.log([row["rate"] for row in rows])
        results["discharge"]["exponent_fit"] = float(np.polyfit(x, y, 1)[0])
    print(f"\ndischarge (fit {args.fit[0]}-{args.fit[1]} s; Beverloo slot C' = {BEVERLOO_SLOT_C}, k = {BEVERLOO_K}, "
          f"d = {diameter * 1000:.1f} mm, rho_b = {bulk_density:.0f} kg/m^3)")
    print(f"{'b mm':>6} {'b/d':>5} {'W kg/s':>8} {'Beverloo':>9} {'ratio':>6} {'nonlinear':>9}")
    for row in rows:
        print(f"{row['slot'] * 1000:6.1f} {row['slot_over_d']:5.2f} {row['rate']:8.4f} {row['beverloo']:9.4f} "
              f"{row['ratio']:6.3f} {row['nonlinearity']:9.3f}")
    if "exponent_fit" in results["discharge"]:
        print(f"fitted exponent of (b - k d): {results['discharge']['exponent_fit']:.2f} (Beverloo slot: 1.5)")

    args.json.parent.mkdir(parents=True, exist_ok=True)
    args.json.write_text(json.dumps(results, indent=1))
    print(f"results: {args.json}")
    if args.plots:
        plot(results, args.plots)
    return 0


def plot(results: dict, folder: Path) -> None:
    from pdemfem.plot import agg_pyplot

    plt = agg_pyplot()
    folder.mkdir(parents=True, exist_ok=True)
    diameter = results["diameter"]
    closed = results["closed"]
    bulk_density = closed[0]["bulk_density"]

    if results["discharge"]["rows"]:
        figure, (left, right) = plt.subplots(1, 2, figsize=(9, 3.6))
        for row in results["discharge"]["rows"]:
            left.plot(row["time"], row["mass_out"], label=f"b = {row['slot'] * 1000:.0f} mm")
        left.axvspan(*results["discharge"]["fit_window"], color="0.9")
        left.set_xlabel("time [s]")
        left.set_ylabel("mass_out [kg]")
        left.legend()
        slots = np.linspace(min(row["slot"] for row in results["discharge"]["rows"]) * 0.8,
                            max(row["slot"] for row in results["discharge"]["rows"]) * 1.1, 50)
        right.plot(slots * 1000, [beverloo_slot(bulk_density, s, diameter) for s in slots], "k-",
                   label="Beverloo (slot, C' = 1.03, k = 1.4)")
        right.plot([row["slot"] * 1000 for row in results["discharge"]["rows"]],
                   [row["rate"] for row in results["discharge"]["rows"]], "o", label="pdemfem")
        right.set_xlabel("slot width b [mm]")
        right.set_ylabel("discharge rate W [kg/s]")
        right.legend()
        figure.tight_layout()
        figure.savefig(folder / "hopper_beverloo.png", dpi=110)
        plt.close(figure)

    figure, axes = plt.subplots(figsize=(5.2, 4.0))
    markers = "os^v"
    for index, run in enumerate(closed):
        rows = run["rows"]
        label = ("floor at rest" if run["floor_speed"] == 0 else f"floor sinking {run['floor_speed'] * 1000:.0f} mm/s")
        axes.plot([row["stress"] for row in rows], [row["depth"] * 1000 for row in rows], markers[index % 4],
                  label=f"pdemfem, {label} (floor: {run['floor_share_of_weight']:.0%} of the weight)")
    run = closed[-1]
    depth = np.linspace(0, max(entry["free_surface"] for entry in closed), 60)
    axes.plot(janssen_wall_stress(depth, run["bulk_density"], results["wall_friction"], run["k_jaky"],
                                  run["hydraulic_diameter"]), depth * 1000, "k-",
              label=f"Janssen, K = 1 - sin phi = {run['k_jaky']:.2f}")
    axes.plot(janssen_wall_stress(depth, run["bulk_density"], results["wall_friction"], run["k_direct"],
                                  run["hydraulic_diameter"]), depth * 1000, "k--",
              label=f"Janssen, K = sigma_w / sigma_v at the floor = {run['k_direct']:.2f}")
    axes.plot(run["k_jaky"] * run["bulk_density"] * GRAVITY * depth, depth * 1000, ":", color="0.5",
              label="K rho_b g z (no wall friction)")
    axes.invert_yaxis()
    axes.set_xlabel("wall normal stress [Pa]")
    axes.set_ylabel("depth below the free surface [mm]")
    axes.legend(fontsize=7)
    figure.tight_layout()
    figure.savefig(folder / "hopper_janssen.png", dpi=110)
    plt.close(figure)


if __name__ == "__main__":
    sys.exit(main())

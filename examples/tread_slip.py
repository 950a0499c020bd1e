"""Traction and vertical load of the lugged wheel of examples/tread.yaml against slip.

    python examples/tread_slip.py [--slips 0 0.1 0.2 0.3 0.5] [--ranks 1] [--out out/tread_slip]
                                  [--png docs/img/tread_slip.png]

Runs the scene once per slip s with the wheel's spin set to omega = V / (R (1 - s)) (V its forward speed,
R = 0.08 m its carcass radius, lugs excluded; s = 0: the carcass would roll without slipping, s > 0: a
driven wheel), each with `pdemfem run` (under `python -m pdemfem.launch -n RANKS`), then reads each run's
history.csv and averages, over the window in which the wheel runs through the level bed (t >= --from),
the particles' force on the wheel: traction F_x (forward positive: the drawbar pull a driven wheel
delivers; negative: motion resistance) and vertical load F_z.  It also reads the bed's surface at the end
of each run (particles.h5): ahead of the wheel, the sinkage of the lug tips below it (the axle height is
prescribed: this sinkage is set by the scene, the load F_z is the result), and behind it the depth of the
rut the wheel leaves (the bed it compacted and the gravel its slipping lugs threw back).
Writes <out>/tread_slip.json and a plot (traction, load and F_x/F_z against slip).
"""
from __future__ import annotations

import argparse
import json
import subprocess
import sys
from pathlib import Path

import numpy as np
import yaml

HERE = Path(__file__).resolve().parent
CARCASS_RADIUS = 0.08   # [m] examples/meshes/tread_wheel.geo: the rim at 0.06, the carcass at 0.08,
LUG_TIP_RADIUS = 0.088  # 8 mm lugs


def scene_for_slip(scene: dict, slip: float) -> dict:
    """The scene with the wheel's spin for `slip` (its forward speed kept)."""
    scene = yaml.safe_load(yaml.safe_dump(scene))
    motion = scene["solids"][0]["motion"]
    speed = float(motion["velocity"][0])
    motion["angular_velocity"] = [0.0, speed / (CARCASS_RADIUS * (1.0 - slip)), 0.0]
    return scene


def run(scene_path: Path, slip: float, out: Path, ranks: int) -> Path:
    scene = scene_for_slip(yaml.safe_load(scene_path.read_text()), slip)
    # Relative mesh paths stay valid: the scene copy is written next to the original.
    copy = scene_path.parent / f".tread_slip_{slip:.3f}.yaml"
    copy.write_text(yaml.safe_dump(scene))
    target = out / f"slip_{slip:.2f}"
    try:
        subprocess.run([sys.executable, "-m", "pdemfem.launch", "-n", str(ranks), "--", sys.executable, "-m",
                        "pdemfem.cli", "run", str(copy), "-o", str(target), "--force", "--quiet"], check=True)
    finally:
        copy.unlink(missing_ok=True)
    return target


def bed_surface(run_dir: Path, speed: float, start: float, stop: float, half_width: float,
                motion_start: float = 0.0) -> float:
    """Height [m] of the bed's surface between start and stop [m] ahead of the axle (negative: behind it) at
    the last output step, within |y| < half_width: the mean over 1 cm bins along x of the highest particle
    top (centre + radius) in each bin."""
    import h5py

    with h5py.File(run_dir / "particles.h5", "r") as handle:
        steps = sorted(name for name in handle if name.startswith("step_"))
        last = handle[steps[-1]]
        positions, radii, time = last["positions"][...], last["radii"][...], float(last.attrs["time"])
    axle = speed * max(0.0, time - motion_start)
    tops = []
    for left in np.arange(axle + start, axle + stop - 1e-9, 0.01):
        inside = ((positions[:, 0] >= left) & (positions[:, 0] < left + 0.01)
                  & (np.abs(positions[:, 1]) < half_width))
        if inside.any():
            tops.append(float((positions[inside, 2] + radii[inside]).max()))
    return float(np.mean(tops)) if tops else float("nan")


def summarize(run_dir: Path, window_start: float, speed: float, motion_start: float = 0.0) -> dict:
    from pdemfem.plot import read_history

    history = read_history(run_dir / "history.csv")
    window = history["time"] >= window_start
    traction = history["mean_force_wheel_x"][window]
    load = history["mean_force_wheel_z"][window]
    # The level bed 4-12 cm ahead of the axle, and the rut the wheel (40 mm wide) leaves 6-12 cm behind it.
    surface = bed_surface(run_dir, speed, 0.04, 0.12, 0.034, motion_start)
    rut = bed_surface(run_dir, speed, -0.12, -0.06, 0.015, motion_start)
    # A free axis (motion.carried_mass) finds its own height; a prescribed one stays at z = 0.
    axle = float(history["axle_height_wheel"][window].mean()) if "axle_height_wheel" in history else 0.0
    return {"traction": float(traction.mean()), "traction_std": float(traction.std()),
            "load": float(load.mean()), "load_std": float(load.std()),
            "traction_coefficient": float(traction.mean() / load.mean()),
            "sinkage": float(surface - (axle - LUG_TIP_RADIUS)), "rut_depth": float(surface - rut),
            "axle_height": axle,
            "frame_work": float(history["frame_work"][-1]),
            "rows": int(window.sum())}


def plot(results: dict, png: Path) -> None:
    import matplotlib

    matplotlib.use("Agg")
    from matplotlib import pyplot

    slips = sorted(results)
    figure, (forces, ratio, depth) = pyplot.subplots(1, 3, figsize=(13, 3.8))
    forces.errorbar(slips, [results[s]["traction"] for s in slips], [results[s]["traction_std"] for s in slips],
                    marker="o", capsize=3, label="traction F_x")
    forces.errorbar(slips, [results[s]["load"] for s in slips], [results[s]["load_std"] for s in slips],
                    marker="s", capsize=3, label="vertical load F_z")
    forces.axhline(0.0, color="0.6", lw=0.8)
    forces.set_xlabel("slip s = 1 - V / (omega R)")
    forces.set_ylabel("force of the gravel on the wheel [N]")
    forces.legend(fontsize="small")
    forces.grid(alpha=0.3)
    ratio.plot(slips, [results[s]["traction_coefficient"] for s in slips], marker="o")
    ratio.axhline(0.0, color="0.6", lw=0.8)
    ratio.set_xlabel("slip s")
    ratio.set_ylabel("F_x / F_z")
    ratio.grid(alpha=0.3)
    depth.plot(slips, [1000 * results[s]["sinkage"] for s in slips], marker="o", label="lug-tip sinkage")
    depth.plot(slips, [1000 * results[s]["rut_depth"] for s in slips], marker="s", label="rut depth behind")
    depth.set_xlabel("slip s")
    depth.set_ylabel("[mm]")
    depth.legend(fontsize="small")
    depth.grid(alpha=0.3)
    free = any("axle_height" in r and r["axle_height"] != 0.0 for r in results.values())
    figure.suptitle(("lugged wheel sinking freely under its load" if free else "lugged wheel at a fixed axle height")
                    + " in gravel (mean and spread over the level bed)", fontsize="medium")
    figure.tight_layout()
    png.parent.mkdir(parents=True, exist_ok=True)
    figure.savefig(png, dpi=110)
    pyplot.close(figure)


def main(argv=None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("--scene", type=Path, default=HERE / "tread.yaml")
    parser.add_argument("--slips", type=float, nargs="+", default=[0.0, 0.1, 0.2, 0.3, 0.5])
    parser.add_argument("--ranks", type=int, default=1)
    parser.add_argument("--out", type=Path, default=Path("out/tread_slip"))
    parser.add_argument("--from", dest="window_start", type=float, default=0.3,
                        help="average from this time [s] (default 0.3: the wheel is past the bed's sloped end)")
    parser.add_argument("--png", type=Path, default=None, help="plot file (default <out>/tread_slip.png)")
    parser.add_argument("--reuse", action="store_true", help="summarize existing runs in --out, run nothing")
    args = parser.parse_args(argv)
    motion = yaml.safe_load(args.scene.read_text())["solids"][0]["motion"]
    speed, motion_start = float(motion["velocity"][0]), float(motion.get("start", 0.0))
    results = {}
    for slip in args.slips:
        target = args.out / f"slip_{slip:.2f}" if args.reuse else run(args.scene, slip, args.out, args.ranks)
        results[slip] = summarize(target, args.window_start, speed, motion_start)
    print(f"{'slip':>5} {'traction F_x [N]':>18} {'load F_z [N]':>14} {'F_x/F_z':>8} {'sinkage [mm]':>13} "
          f"{'rut depth [mm]':>15}")
    for slip in sorted(results):
        r = results[slip]
        print(f"{slip:5.2f} {r['traction']:9.3f} +- {r['traction_std']:5.3f} {r['load']:7.3f} +- {r['load_std']:4.2f}"
              f" {r['traction_coefficient']:8.3f} {1000 * r['sinkage']:13.1f} {1000 * r['rut_depth']:15.1f}")
    args.out.mkdir(parents=True, exist_ok=True)
    (args.out / "tread_slip.json").write_text(json.dumps({f"{s:.2f}": r for s, r in results.items()}, indent=2))
    plot(results, args.png or args.out / "tread_slip.png")
    return 0


if __name__ == "__main__":
    sys.exit(main())

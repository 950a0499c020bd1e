"""A picture of a run's last output step (matplotlib, Agg backend: no display needed), and the gallery.

    render_output("out/drum", scene="examples/drum.yaml")    -> out/drum/render.png
    build_gallery()                                           -> docs/img/gallery/<example>.png, docs/gallery.md

The picture is drawn from what the run wrote: the particles of the last step of ``particles.h5``
(spheres drawn as markers sized by ``radii``, coloured by speed when ``velocities`` was written), each
solid's boundary from ``<solid>.h5`` displaced by its last ``displacements`` (coloured by the
displacement's magnitude), and, when the scene is given, its walls: mesh walls as their triangles,
cylinders as their mantle, planes as translucent rectangles clipped to the picture's bounding box.
The run's files are read serially with h5py (rank 0); nothing is gathered from a running job.
"""
from __future__ import annotations

import math
import warnings
from pathlib import Path
from typing import List, Optional

import numpy as np

from pdemfem.errors import PdemfemError

__all__ = ["render_output", "build_gallery", "GALLERY_DIR", "GALLERY_PAGE"]

ROOT = Path(__file__).resolve().parent.parent
EXAMPLES_DIR = ROOT / "examples"
GALLERY_DIR = ROOT / "docs" / "img" / "gallery"
GALLERY_PAGE = ROOT / "docs" / "gallery.md"
# Pictures for the repository stay small (a gallery of a few examples must not bloat the history).
PICTURE_INCHES = (5.0, 4.0)
PICTURE_DPI = 90


# --------------------------------------------------------------------------- reading a run


def _last_step(path: Path, fields):
    """(time, {field: array}) of the last step group of an output file; only the fields present."""
    import h5py

    with h5py.File(path, "r") as handle:
        steps = sorted(name for name in handle if name.startswith("step_"))
        if not steps:
            raise PdemfemError(str(path), "no output step in the file", "let the run write at least one output step")
        group = handle[steps[-1]]
        return float(group.attrs.get("time", 0.0)), {name: np.asarray(group[name]) for name in fields if name in group}


def _solid_surface(path: Path):
    """(deformed boundary triangles (nf, 3, 3), |u| per triangle) of a solid's last output step."""
    import h5py

    from pdemfem.fem.mesh import boundary_faces

    with h5py.File(path, "r") as handle:
        points = np.asarray(handle["mesh/points"])
        cells = np.asarray(handle["mesh/cells"], dtype=np.int64)
    _, last = _last_step(path, ["displacements"])
    displacements = last.get("displacements", np.zeros_like(points))
    faces = boundary_faces(cells)
    moved = points + displacements
    magnitude = np.linalg.norm(displacements, axis=1)
    return moved[faces], magnitude[faces].mean(axis=1)


# --------------------------------------------------------------------------- walls


def _wall_polygons(scene, base_dir: Path, low: np.ndarray, high: np.ndarray) -> List[np.ndarray]:
    """Polygons (each (k, 3)) drawing the scene's walls inside the box [low, high]."""
    polygons: List[np.ndarray] = []
    for wall in scene.walls:
        if wall.kind == "mesh":
            from pdemfem.walls.readers import read_surface

            vertices, triangles = read_surface(Path(base_dir) / wall.file, wall.scale)
            polygons.extend(vertices[triangles])
        elif wall.kind == "cylinder":
            polygons.extend(_cylinder_strips(wall, low, high))
        elif wall.kind == "plane":
            polygon = _plane_rectangle(np.array(wall.point, float), np.array(wall.normal, float), low, high)
            if polygon is not None:
                polygons.append(polygon)
    return polygons


def _finite_wall_points(scene, base_dir: Path, extents) -> List[np.ndarray]:
    """Points bounding the finite walls: mesh-wall vertices, and each cylinder's cross-section at the
    ends of what else is drawn along its axis (a drum is shown whole, not cut at the particles)."""
    points: List[np.ndarray] = []
    others = np.vstack(extents) if extents else np.zeros((0, 3))
    for wall in scene.walls:
        if wall.kind == "mesh":
            from pdemfem.walls.readers import read_surface

            points.append(read_surface(Path(base_dir) / wall.file, wall.scale)[0])
        elif wall.kind == "cylinder" and len(others):
            point = np.array(wall.axis.point, float)
            direction = np.array(wall.axis.direction, float)
            direction /= np.linalg.norm(direction)
            along = (others - point) @ direction
            first, second = _frame(direction)
            for position in (along.min(), along.max()):
                centre = point + position * direction
                points.append(np.array([centre + sign * wall.radius * axis
                                        for axis in (first, second) for sign in (-1.0, 1.0)]))
    return points


def _frame(direction: np.ndarray):
    """Two unit vectors orthogonal to `direction` and to each other."""
    direction = direction / np.linalg.norm(direction)
    helper = np.eye(3)[int(np.argmin(np.abs(direction)))]
    first = np.cross(direction, helper)
    first /= np.linalg.norm(first)
    return first, np.cross(direction, first)


def _plane_rectangle(point, normal, low, high) -> Optional[np.ndarray]:
    """The plane's rectangle spanning the box's corners projected onto it (None if it misses the box)."""
    normal = normal / np.linalg.norm(normal)
    corners = np.array([[x, y, z] for x in (low[0], high[0]) for y in (low[1], high[1]) for z in (low[2], high[2])])
    heights = (corners - point) @ normal
    if heights.min() > 0 or heights.max() < 0:
        return None
    first, second = _frame(normal)
    u, v = (corners - point) @ first, (corners - point) @ second
    return np.array([point + a * first + b * second
                     for a, b in ((u.min(), v.min()), (u.max(), v.min()), (u.max(), v.max()), (u.min(), v.max()))])


def _cylinder_strips(wall, low, high, segments: int = 48) -> List[np.ndarray]:
    """The cylinder's mantle between the box's extreme points along its axis, as quads."""
    point = np.array(wall.axis.point, float)
    direction = np.array(wall.axis.direction, float)
    direction /= np.linalg.norm(direction)
    corners = np.array([[x, y, z] for x in (low[0], high[0]) for y in (low[1], high[1]) for z in (low[2], high[2])])
    along = (corners - point) @ direction
    start, end = along.min(), along.max()
    first, second = _frame(direction)
    angles = np.linspace(0.0, 2.0 * math.pi, segments + 1)
    ring = [wall.radius * (math.cos(a) * first + math.sin(a) * second) for a in angles]
    return [np.array([point + start * direction + ring[k], point + start * direction + ring[k + 1],
                      point + end * direction + ring[k + 1], point + end * direction + ring[k]])
            for k in range(segments)]


# --------------------------------------------------------------------------- drawing


def _pyplot():
    import matplotlib

    matplotlib.use("Agg")
    with warnings.catch_warnings():
        warnings.simplefilter("ignore", UserWarning)
        from matplotlib import pyplot
        from mpl_toolkits.mplot3d.art3d import Poly3DCollection
    return pyplot, Poly3DCollection


def render_output(outdir, scene=None, target=None, title: Optional[str] = None) -> Path:
    """Draw the last output step of the run in `outdir` into `target` (default OUTDIR/render.png).

    `scene`: the scene file the run used (its walls are drawn, its solids' names found); without it
    the particles and every ``<solid>.h5`` beside them are drawn."""
    outdir = Path(outdir)
    if not outdir.is_dir():
        raise PdemfemError(str(outdir), "no such output directory", "run a scene first: pdemfem run scene.yaml -o DIR")
    loaded = None
    if scene is not None:
        from pdemfem.scene.loader import load_scene

        loaded = load_scene(scene)
    particles_file = outdir / "particles.h5"
    time = None
    positions = np.zeros((0, 3))
    radii = np.zeros(0)
    speeds = None
    if particles_file.is_file():
        time, fields = _last_step(particles_file, ["positions", "radii", "velocities"])
        if "positions" not in fields:
            raise PdemfemError(str(particles_file), "the run wrote no particle positions",
                               "add positions to output.particles and re-run")
        positions = fields["positions"]
        radii = fields.get("radii", np.full(len(positions), 0.0))
        if "velocities" in fields:
            speeds = np.linalg.norm(fields["velocities"], axis=1)
    if loaded is not None:
        solid_names = [solid.name for solid in loaded[0].solids]
    else:
        solid_names = [path.stem for path in sorted(outdir.glob("*.h5"))
                       if path.stem != "particles" and (outdir / f"{path.stem}.xdmf").is_file()]
    surfaces = [_solid_surface(outdir / f"{name}.h5") for name in solid_names if (outdir / f"{name}.h5").is_file()]
    if not len(positions) and not surfaces:
        raise PdemfemError(str(outdir), "no particles.h5 or solid series to draw",
                           "run with output.particles (positions, radii) or solids in the scene")

    # The picture's box: the particles (with their radii), the solids, mesh walls and cylinder
    # cross-sections; planes (infinite) are clipped to it.
    extents = [positions - radii[:, None], positions + radii[:, None]] if len(positions) else []
    extents += [triangles.reshape(-1, 3) for triangles, _ in surfaces]
    if loaded is not None:
        extents += _finite_wall_points(loaded[0], loaded[1], extents)
    everything = np.vstack(extents)
    low, high = everything.min(axis=0), everything.max(axis=0)
    margin = 0.05 * float((high - low).max())
    low, high = low - margin, high + margin
    if len(radii):
        # A scene of a few spheres (a collision, a rolling ball) is shown with room around them.
        least = 6.0 * 2.0 * float(radii.max())
        centre = 0.5 * (low + high)
        low, high = np.minimum(low, centre - 0.5 * least), np.maximum(high, centre + 0.5 * least)

    pyplot, Poly3DCollection = _pyplot()
    figure = pyplot.figure(figsize=PICTURE_INCHES)
    axes = figure.add_subplot(projection="3d")
    # Draw walls, then solids, then particles: mplot3d sorts whole collections by depth, which hides
    # grains resting on a solid's top behind the solid.
    axes.computed_zorder = False
    if loaded is not None and loaded[0].walls:
        polygons = _wall_polygons(loaded[0], loaded[1], low, high)
        if polygons:
            axes.add_collection3d(Poly3DCollection(polygons, facecolor=(0.6, 0.6, 0.65, 0.12),
                                                   edgecolor=(0.3, 0.3, 0.35, 0.15), linewidths=0.3,
                                                   zorder=0))
    for triangles, magnitude in surfaces:
        colours = pyplot.get_cmap("plasma")(magnitude / magnitude.max() if magnitude.max() > 0 else magnitude)
        axes.add_collection3d(Poly3DCollection(triangles, facecolor=colours, edgecolor=(0, 0, 0, 0.15),
                                               linewidths=0.2, alpha=0.9, zorder=1))
    span = float((high - low).max())
    axes.set_xlim(low[0], high[0])
    axes.set_ylim(low[1], high[1])
    axes.set_zlim(low[2], high[2])
    axes.set_box_aspect(tuple(high - low))  # true proportions
    if len(positions):
        # Marker area in points^2: a sphere's diameter as a fraction of the largest span, times the
        # longest axis's drawn length in points (about 0.45 of the figure's width at the default view).
        points_per_metre = 0.45 * PICTURE_INCHES[0] * 72.0 / span
        sizes = (2.0 * radii * points_per_metre) ** 2
        colour = speeds if speeds is not None else "tab:blue"
        drawn = axes.scatter(positions[:, 0], positions[:, 1], positions[:, 2], s=sizes, c=colour,
                             cmap="viridis", depthshade=True, edgecolors="none", zorder=2)
        if speeds is not None:
            bar = figure.colorbar(drawn, ax=axes, shrink=0.6, pad=0.1)
            bar.set_label("speed [m/s]")
    axes.set_xlabel("x [m]", fontsize="small")
    axes.set_ylabel("y [m]", fontsize="small")
    axes.set_zlabel("z [m]", fontsize="small")
    axes.tick_params(labelsize="x-small")
    label = title or outdir.name
    axes.set_title(f"{label}" + (f", t = {time:.3g} s" if time is not None else ""), fontsize="medium")
    target = Path(target) if target is not None else outdir / "render.png"
    target.parent.mkdir(parents=True, exist_ok=True)
    figure.savefig(target, dpi=PICTURE_DPI)
    pyplot.close(figure)
    return target


# --------------------------------------------------------------------------- gallery


def _first_comment(path: Path) -> str:
    """The opening comment of an example (what it shows): its comment lines up to the first command
    line (indented, "#   pdemfem ...") or the first key."""
    lines = []
    for line in path.read_text().splitlines():
        if not line.startswith("#") or line.startswith("#  "):
            break
        lines.append(line[1:].strip())
    return " ".join(lines)


def build_gallery(comm, runs_dir, examples=None, say=print) -> List[Path]:
    """Run every example (collective over `comm`), draw each one's last step into GALLERY_DIR and
    write GALLERY_PAGE.  Returns the pictures written (on rank 0; [] elsewhere)."""
    from pdemfem.simulation import Simulation

    paths = [Path(path) for path in examples] if examples else sorted(EXAMPLES_DIR.glob("*.yaml"))
    runs_dir = Path(runs_dir)
    written: List[Path] = []
    for path in paths:
        output = runs_dir / path.stem
        say(f"running {path} -> {output}")
        simulation = Simulation.from_file(path, comm=comm, output_dir=output, force=True)
        simulation.run(progress=False)
        failure = None
        if comm.rank == 0:
            try:
                written.append(render_output(output, scene=path, target=GALLERY_DIR / f"{path.stem}.png",
                                             title=path.stem))
                say(f"wrote {written[-1]}")
            except PdemfemError as error:
                failure = (error.where, error.problem, error.fix)
        # Rank 0 draws while the others wait for the next example: all ranks stop on its error together.
        failure = comm.bcast(failure, root=0)
        if failure is not None:
            raise PdemfemError(*failure)
    if comm.rank == 0 and not examples:
        GALLERY_PAGE.write_text(_gallery_page(paths))
        say(f"wrote {GALLERY_PAGE}")
    return written


def _gallery_page(paths) -> str:
    lines = ["# Gallery", "",
             "<!-- Written by `pdemfem render --gallery`, which runs every examples/*.yaml and draws its last "
             "output step. -->", "",
             "The last output step of every example in `examples/`, as `pdemfem render --gallery` draws it",
             "(particles coloured by speed, solids by the magnitude of their displacement, walls translucent).",
             "Run one yourself: `pdemfem run examples/<name>.yaml -o out/<name>`, then",
             "`pdemfem render out/<name> --scene examples/<name>.yaml`, or open the XDMF files in ParaView",
             "(docs/output.md).", ""]
    for path in paths:
        lines += [f"## {path.stem}", "", _first_comment(path), "",
                  f"![{path.stem}](img/gallery/{path.stem}.png)", "",
                  f"Scene: [examples/{path.name}](../examples/{path.name})", ""]
    return "\n".join(lines)

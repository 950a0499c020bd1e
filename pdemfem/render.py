"""A picture of a run's last output step, headless, and the gallery.

    render_output("out/drum", scene="examples/drum.yaml")    -> out/drum/render.png
    build_gallery()                                           -> docs/img/gallery/<example>.png, docs/gallery.md

The picture is drawn from what the run wrote: the particles of the last step of ``particles.h5``
(spheres sized by ``radii``, coloured by speed when ``velocities`` was written), each solid's
boundary from ``<solid>.h5`` displaced by its last ``displacements`` (coloured by the
displacement's magnitude), and, when the scene is given, its walls: mesh walls as their triangles,
cylinders as their mantle, planes as translucent rectangles clipped to the picture's bounding box.
Two renderers: ParaView, by render_paraview.py run in ParaView's own ``pvpython`` (a subprocess,
offscreen; sphere glyphs, the XDMF files read by ParaView's Xdmf3 reader), used when pvpython is
found; and matplotlib (Agg backend, mplot3d: spheres as sized markers) otherwise, or when
pvpython fails ("auto" says why in one line).  The run's files are read serially with h5py
(rank 0); nothing is gathered from a running job.
"""
from __future__ import annotations

import contextlib
import math
import os
import shutil
import sys
import warnings
from pathlib import Path
from typing import Callable, List, Optional

import numpy as np

from pdemfem.errors import PdemfemError

__all__ = ["render_output", "draw_output", "choose_renderer", "build_gallery", "GALLERY_DIR", "GALLERY_PAGE"]

ROOT = Path(__file__).resolve().parent.parent
EXAMPLES_DIR = ROOT / "examples"
GALLERY_DIR = ROOT / "docs" / "img" / "gallery"
GALLERY_PAGE = ROOT / "docs" / "gallery.md"
# Pictures for the repository stay small (a gallery of a few examples must not bloat the history).
PICTURE_INCHES = (5.0, 4.0)
PICTURE_DPI = 90
PICTURE_SIZE = (round(PICTURE_INCHES[0] * PICTURE_DPI), round(PICTURE_INCHES[1] * PICTURE_DPI))  # pixels
PVPYTHON_VARIABLE = "PDEMFEM_PVPYTHON"


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
    _, last = _last_step(path, ["displacements", "elastic_displacements"])
    displacements = last.get("displacements", np.zeros_like(points))
    faces = boundary_faces(cells)
    moved = points + displacements
    # A solid under motion: coloured by its deformation, not by how far its frame carried it.
    magnitude = np.linalg.norm(last.get("elastic_displacements", displacements), axis=1)
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


def _prefer_the_toolkit_beside(matplotlib) -> None:
    """Look for mpl_toolkits.mplot3d first beside the matplotlib in use.  An older system matplotlib (e.g.
    Debian's python3-matplotlib, which ParaView's package brings) beside an environment's newer one ships
    mpl_toolkits as a regular package, which wins over the newer one's namespace package and does not
    import with the newer matplotlib."""
    own = Path(matplotlib.__file__).resolve().parent.parent / "mpl_toolkits"
    if not (own / "mplot3d").is_dir() or "mpl_toolkits.mplot3d" in sys.modules:
        return
    import mpl_toolkits

    search = mpl_toolkits.__path__
    if isinstance(search, list) and str(own) not in search:  # a namespace package's path already holds it
        search.insert(0, str(own))


def _pyplot():
    import matplotlib

    matplotlib.use("Agg")
    with warnings.catch_warnings():
        warnings.simplefilter("ignore", UserWarning)
        _prefer_the_toolkit_beside(matplotlib)  # before pyplot, whose projections register mplot3d's '3d'
        from matplotlib import pyplot
        try:
            from mpl_toolkits.mplot3d import Axes3D
            from mpl_toolkits.mplot3d.art3d import Poly3DCollection
        except ImportError as error:
            raise PdemfemError("matplotlib's 3-D toolkit (mpl_toolkits.mplot3d)", f"does not import: {error}",
                               f"two matplotlib installations are mixed (this one: {matplotlib.__file__}); "
                               "keep one: remove the system's (apt-get remove python3-matplotlib) or this "
                               "environment's (pip uninstall matplotlib), or draw with --renderer paraview") from None
        from matplotlib import projections
        if "3d" not in projections.get_projection_names():
            # pyplot was imported before (by `plot`, in the same process) when the system's toolkit still came
            # first: its registration of '3d' failed then, with a warning only.
            projections.register_projection(Axes3D)
    return pyplot, Poly3DCollection


def render_output(outdir, scene=None, target=None, title: Optional[str] = None, renderer: str = "auto",
                  pvpython: Optional[str] = None, warn: Optional[Callable[[str], None]] = None) -> Path:
    """Draw the last output step of the run in `outdir` into `target` (default OUTDIR/render.png).

    `scene`: the scene file the run used (its walls are drawn, its solids' names found); without it
    the particles and every ``<solid>.h5`` beside them are drawn.  `renderer`: "auto" (ParaView's
    pvpython when found, else matplotlib), "paraview" or "matplotlib"; `pvpython`: its path (default
    ``$PDEMFEM_PVPYTHON``, then ``pvpython`` on PATH).  `warn` receives the one-line reason when
    "auto" falls back from ParaView to matplotlib (default: printed to stderr)."""
    return draw_output(outdir, scene, target, title, renderer, pvpython, warn)[0]


def draw_output(outdir, scene=None, target=None, title: Optional[str] = None, renderer: str = "auto",
                pvpython: Optional[str] = None, warn: Optional[Callable[[str], None]] = None):
    """render_output, returning (picture, the renderer that drew it, e.g. "ParaView 5.11.0")."""
    executable = choose_renderer(renderer, pvpython)
    picture = _Picture.gather(Path(outdir), scene)
    target = Path(target) if target is not None else picture.outdir / "render.png"
    target.parent.mkdir(parents=True, exist_ok=True)
    label = title or picture.outdir.name
    if executable is not None:
        try:
            version = _draw_paraview(executable, picture, target, label)
            return target, f"ParaView {version}"
        except ParaViewFailed as failure:
            if renderer == "paraview":
                raise PdemfemError(f"pdemfem render --renderer paraview ({executable})", str(failure),
                                   "see docs/output.md, 'A picture of a run' (an X11 build of ParaView needs Xvfb "
                                   "when there is no display), or use --renderer matplotlib") from None
            (warn or _to_stderr)(f"ParaView could not draw {target.name} ({failure}); drawing it with matplotlib")
    _draw_matplotlib(picture, target, label)
    import matplotlib

    return target, f"matplotlib {matplotlib.__version__}"


def _to_stderr(text: str) -> None:
    print(text, file=sys.stderr, flush=True)


RENDERERS = ("auto", "paraview", "matplotlib")


def find_pvpython(pvpython: Optional[str] = None) -> Optional[str]:
    """The pvpython to use: `pvpython` if given, else $PDEMFEM_PVPYTHON, else pvpython on PATH (or None).
    A path that is given but not an executable is an error (a typo must not silently mean matplotlib)."""
    given, key = (pvpython, "--pvpython") if pvpython else (os.environ.get(PVPYTHON_VARIABLE), PVPYTHON_VARIABLE)
    if not given:
        return shutil.which("pvpython")
    found = shutil.which(given)
    if found is None:
        raise PdemfemError(f"{key} {given}", "no such executable",
                           f"give the path of ParaView's pvpython, or unset {key} to use pvpython on PATH")
    return found


def choose_renderer(renderer: str, pvpython: Optional[str] = None) -> Optional[str]:
    """The pvpython to draw with, or None for matplotlib (checked before anything is read or run)."""
    if renderer not in RENDERERS:
        raise PdemfemError("--renderer", f"unknown renderer {renderer!r}", "use auto, paraview or matplotlib")
    if renderer == "matplotlib":
        return None
    executable = find_pvpython(pvpython)
    if executable is None and renderer == "paraview":
        raise PdemfemError("--renderer paraview", "pvpython (ParaView's Python) is not on PATH",
                           "install ParaView (Debian/Ubuntu: apt-get install paraview), or give its pvpython with "
                           f"--pvpython PATH or {PVPYTHON_VARIABLE}=PATH, or use --renderer matplotlib")
    return executable


class _Picture:
    """What a picture shows, read from a run's files: the last step's particles and solid surfaces,
    the scene's walls, and the box [low, high] that holds them."""

    def __init__(self, outdir, loaded, time, positions, radii, speeds, solid_names, surfaces, low, high,
                 temperatures=None):
        self.outdir, self.loaded, self.time = outdir, loaded, time
        self.positions, self.radii, self.speeds = positions, radii, speeds
        # With heat on the particles are coloured by temperature instead of speed.
        self.temperatures = temperatures
        self.solid_names, self.surfaces, self.low, self.high = solid_names, surfaces, low, high

    @classmethod
    def gather(cls, outdir: Path, scene) -> "_Picture":
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
        temperatures = None
        if particles_file.is_file():
            time, fields = _last_step(particles_file, ["positions", "radii", "velocities", "temperature"])
            if "positions" not in fields:
                raise PdemfemError(str(particles_file), "the run wrote no particle positions",
                                   "add positions to output.particles and re-run")
            positions = fields["positions"]
            radii = fields.get("radii", np.full(len(positions), 0.0))
            if "velocities" in fields:
                speeds = np.linalg.norm(fields["velocities"], axis=1)
            temperatures = fields.get("temperature")
        if loaded is not None:
            solid_names = [solid.name for solid in loaded[0].solids]
        else:
            # Every series but the particles' and the clumps' (clumps.h5: the bodies beside their member spheres).
            solid_names = [path.stem for path in sorted(outdir.glob("*.h5"))
                           if path.stem not in ("particles", "clumps") and (outdir / f"{path.stem}.xdmf").is_file()]
        solid_names = [name for name in solid_names if (outdir / f"{name}.h5").is_file()]
        surfaces = [_solid_surface(outdir / f"{name}.h5") for name in solid_names]
        if not len(positions) and not surfaces:
            if time is not None:  # the series is there; its last step holds no particle
                raise PdemfemError(str(particles_file), f"its last output step (t = {time:.6g} s) holds no particles "
                                                        f"(they left the domain or an outlet took them) and the run "
                                                        f"has no solid series to draw",
                                   "look at an earlier step in ParaView (particles.xdmf), or let the run end before "
                                   "the particles leave")
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
        return cls(outdir, loaded, time, positions, radii, speeds, solid_names, surfaces, low, high,
                   temperatures=temperatures)

    def wall_polygons(self) -> List[np.ndarray]:
        """The scene's walls inside the picture's box (none without the scene)."""
        if self.loaded is None or not self.loaded[0].walls:
            return []
        return _wall_polygons(self.loaded[0], self.loaded[1], self.low, self.high)


def _draw_matplotlib(picture: _Picture, target: Path, label: str) -> None:
    positions, radii, speeds, low, high = picture.positions, picture.radii, picture.speeds, picture.low, picture.high
    pyplot, Poly3DCollection = _pyplot()
    figure = pyplot.figure(figsize=PICTURE_INCHES)
    axes = figure.add_subplot(projection="3d")
    # Draw walls, then solids, then particles: mplot3d sorts whole collections by depth, which hides
    # grains resting on a solid's top behind the solid.
    axes.computed_zorder = False
    polygons = picture.wall_polygons()
    if polygons:
        axes.add_collection3d(Poly3DCollection(polygons, facecolor=(0.6, 0.6, 0.65, 0.12),
                                               edgecolor=(0.3, 0.3, 0.35, 0.15), linewidths=0.3,
                                               zorder=0))
    for triangles, magnitude in picture.surfaces:
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
        hot = picture.temperatures is not None
        colour = picture.temperatures if hot else (speeds if speeds is not None else "tab:blue")
        drawn = axes.scatter(positions[:, 0], positions[:, 1], positions[:, 2], s=sizes, c=colour,
                             cmap="inferno" if hot else "viridis", depthshade=True, edgecolors="none", zorder=2)
        if hot or speeds is not None:
            bar = figure.colorbar(drawn, ax=axes, shrink=0.6, pad=0.1)
            bar.set_label("temperature [K]" if hot else "speed [m/s]")
    axes.set_xlabel("x [m]", fontsize="small")
    axes.set_ylabel("y [m]", fontsize="small")
    axes.set_zlabel("z [m]", fontsize="small")
    axes.tick_params(labelsize="x-small")
    time = picture.time
    axes.set_title(f"{label}" + (f", t = {time:.3g} s" if time is not None else ""), fontsize="medium")
    figure.savefig(target, dpi=PICTURE_DPI)
    pyplot.close(figure)


# --------------------------------------------------------------------------- ParaView (pvpython)


PARAVIEW_SCRIPT = Path(__file__).resolve().parent / "render_paraview.py"
PARAVIEW_SECONDS = 300  # a generous bound: the largest example draws in about 10 s
XVFB_SECONDS = 30  # Xvfb accepts clients well within a second
# matplotlib's default 3-D view, so both renderers look at a scene from the same side.
VIEW_ELEVATION, VIEW_AZIMUTH = 30.0, -60.0


class ParaViewFailed(Exception):
    """pvpython did not produce the picture; the message is the reason in one line."""


def _write_polygons_vtk(path: Path, polygons: List[np.ndarray]) -> None:
    """Polygons as a legacy-VTK POLYDATA file (ASCII), the simplest format every ParaView reads."""
    points = np.vstack(polygons)
    lines = ["# vtk DataFile Version 3.0", "pdemfem walls", "ASCII", "DATASET POLYDATA",
             f"POINTS {len(points)} double"]
    lines += [f"{x!r} {y!r} {z!r}" for x, y, z in points.tolist()]
    lines.append(f"POLYGONS {len(polygons)} {sum(len(polygon) + 1 for polygon in polygons)}")
    start = 0
    for polygon in polygons:
        lines.append(" ".join(str(index) for index in [len(polygon), *range(start, start + len(polygon))]))
        start += len(polygon)
    path.write_text("\n".join(lines) + "\n")


def _one_line(text: str) -> str:
    """The line of a program's error output that names the error: ParaView's first logged error
    ("ERR|", else "FATL|": a crash then ends in a stack trace and "Aborted"), else the last non-empty
    line (a Python traceback's names the exception); without the logger's terminal colour codes."""
    import re

    lines = [re.sub(r"\x1b\[[0-9;]*m", "", line).strip() for line in text.splitlines()]
    for level in ("ERR|", "FATL|"):
        logged = [line.split(level, 1)[1].strip() for line in lines if level in line]
        if logged:
            return logged[0]
    lines = [line for line in lines if line]
    return lines[-1] if lines else ""


@contextlib.contextmanager
def _virtual_display():
    """Extra environment for pvpython: {} normally; {"DISPLAY": ":N"} of a private Xvfb server when
    this is Linux without $DISPLAY and Xvfb is installed.  pvpython's `--force-offscreen-rendering`
    suffices for a ParaView built with EGL or OSMesa, but an X11 build (Debian's) still opens an X
    connection offscreen.  Xvfb picks a free display itself (-displayfd) and writes its number only
    once it accepts clients, so there is no race between servers started one after the other (as
    xvfb-run's --auto-servernum has).  A failed connection shows as "bad X server connection"."""
    import select
    import subprocess

    if not sys.platform.startswith("linux") or os.environ.get("DISPLAY") or not shutil.which("Xvfb"):
        yield {}
        return
    read_end, write_end = os.pipe()
    try:
        # -noreset: by default an X server resets when its last client disconnects, and pvpython
        # connects more than once (an OpenGL probe, then its window): one lands in the reset.
        server = subprocess.Popen(["Xvfb", "-displayfd", str(write_end), "-screen", "0", "1280x1024x24",
                                   "-nolisten", "tcp", "-noreset"], pass_fds=(write_end,), stdin=subprocess.DEVNULL,
                                  stdout=subprocess.DEVNULL, stderr=subprocess.DEVNULL)
    finally:
        os.close(write_end)
    try:
        with os.fdopen(read_end) as pipe:
            ready, _, _ = select.select([pipe], [], [], XVFB_SECONDS)
            number = pipe.readline().strip() if ready else ""
        if not number.isdigit():
            raise ParaViewFailed("the virtual X server (Xvfb) did not start")
        yield {"DISPLAY": f":{number}"}
    finally:
        server.terminate()
        try:
            server.wait(timeout=XVFB_SECONDS)
        except subprocess.TimeoutExpired:
            server.kill()
            server.wait()


def _draw_paraview(pvpython: str, picture: _Picture, target: Path, label: str) -> str:
    """Draw `picture` with render_paraview.py run by `pvpython`, offscreen; returns ParaView's version.
    Raises ParaViewFailed (with the reason) when pvpython fails or writes no picture of the right size."""
    import json
    import subprocess
    import tempfile

    with tempfile.TemporaryDirectory(prefix="pdemfem-render-") as scratch:
        scratch = Path(scratch)
        job = {"particles": None, "solids": [], "walls": None, "target": str(target.resolve()),
               "size": list(PICTURE_SIZE), "title": label,
               "box": [picture.low.tolist(), picture.high.tolist()], "elevation": VIEW_ELEVATION, "azimuth": VIEW_AZIMUTH,
               "color_by_temperature": picture.temperatures is not None}
        if len(picture.positions) and (picture.outdir / "particles.xdmf").is_file():
            job["particles"] = str((picture.outdir / "particles.xdmf").resolve())
        job["solids"] = [str((picture.outdir / f"{name}.xdmf").resolve()) for name in picture.solid_names
                         if (picture.outdir / f"{name}.xdmf").is_file()]
        polygons = picture.wall_polygons()
        if polygons:
            job["walls"] = str(scratch / "walls.vtk")
            _write_polygons_vtk(scratch / "walls.vtk", polygons)
        (scratch / "job.json").write_text(json.dumps(job))
        # pvpython is its own Python: the venv's variables would make it import the wrong packages.  It is
        # also an MPI program (Debian's links Open MPI): what this process's MPI left in the environment
        # (its PMIx server) would make pvpython's MPI start-up join it, which aborts it now and then.
        from pdemfem.runtime import INHERITED_MPI_PREFIXES

        environment = {key: value for key, value in os.environ.items()
                       if key not in ("PYTHONPATH", "PYTHONHOME", "VIRTUAL_ENV")
                       and not key.startswith(INHERITED_MPI_PREFIXES)}
        environment.setdefault("QT_QPA_PLATFORM", "offscreen")
        if target.exists():
            target.unlink()  # a stale picture must not pass for a new one
        command = [pvpython, "--force-offscreen-rendering", str(PARAVIEW_SCRIPT), str(scratch / "job.json")]
        with _virtual_display() as display:
            try:
                completed = subprocess.run(command, capture_output=True, text=True, timeout=PARAVIEW_SECONDS,
                                           env={**environment, **display}, cwd=scratch)
            except subprocess.TimeoutExpired:
                raise ParaViewFailed(f"pvpython did not finish within {PARAVIEW_SECONDS} s") from None
            except OSError as error:
                raise ParaViewFailed(f"cannot run {pvpython}: {error.strerror}") from None
        if completed.returncode != 0:
            reason = _one_line(completed.stderr) or _one_line(completed.stdout)
            if sys.platform.startswith("linux") and "DISPLAY" not in display and not os.environ.get("DISPLAY"):
                reason += ("; " if reason else "") + ("there is no X display, which an X11 build of ParaView needs "
                                                      "even offscreen: install Xvfb (apt-get install xvfb)")
            raise ParaViewFailed(f"pvpython exited with status {completed.returncode}" + (f": {reason}" if reason else ""))
        reports = [line for line in completed.stdout.splitlines() if line.startswith("{")]
        if not reports or not target.is_file():
            raise ParaViewFailed("pvpython wrote no picture" + (f": {_one_line(completed.stderr)}"
                                                                if completed.stderr.strip() else ""))
    size = _png_size(target)
    if size != PICTURE_SIZE:
        raise ParaViewFailed(f"pvpython wrote a {size[0]}x{size[1]} picture, not {PICTURE_SIZE[0]}x{PICTURE_SIZE[1]}")
    return str(json.loads(reports[-1]).get("paraview", "")).strip()


def _png_size(path: Path):
    """(width, height) from a PNG's header (its IHDR chunk); (0, 0) for a file that is no PNG."""
    header = path.read_bytes()[:24]
    if header[:8] != b"\x89PNG\r\n\x1a\n":
        return (0, 0)
    return int.from_bytes(header[16:20], "big"), int.from_bytes(header[20:24], "big")


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


def build_gallery(comm, runs_dir, examples=None, say=print, renderer: str = "auto",
                  pvpython: Optional[str] = None) -> List[Path]:
    """Run every example (collective over `comm`), draw each one's last step into GALLERY_DIR and
    write GALLERY_PAGE (naming the renderer that drew the pictures).  Returns the pictures written
    (on rank 0; [] elsewhere)."""
    from pdemfem.simulation import Simulation

    # A missing pvpython for --renderer paraview is reported before minutes of runs, on every rank.
    executable = pvpython
    if comm.rank == 0:
        try:
            executable = choose_renderer(renderer, pvpython)
            failure = None
        except PdemfemError as error:
            failure = (error.where, error.problem, error.fix)
    failure = comm.bcast(failure if comm.rank == 0 else None, root=0)
    if failure is not None:
        raise PdemfemError(*failure)
    paths = [Path(path) for path in examples] if examples else sorted(EXAMPLES_DIR.glob("*.yaml"))
    runs_dir = Path(runs_dir)
    written: List[Path] = []
    drawn_by: List[str] = []
    for path in paths:
        output = runs_dir / path.stem
        say(f"running {path} -> {output}")
        simulation = Simulation.from_file(path, comm=comm, output_dir=output, force=True)
        simulation.run(progress=False)
        failure = None
        if comm.rank == 0:
            try:
                picture, used = draw_output(output, scene=path, target=GALLERY_DIR / f"{path.stem}.png",
                                            title=path.stem, renderer=renderer, pvpython=executable)
                written.append(picture)
                drawn_by.append(used)
                say(f"wrote {picture} ({used})")
            except PdemfemError as error:
                failure = (error.where, error.problem, error.fix)
        # Rank 0 draws while the others wait for the next example: all ranks stop on its error together.
        failure = comm.bcast(failure, root=0)
        if failure is not None:
            raise PdemfemError(*failure)
    if comm.rank == 0 and not examples:
        GALLERY_PAGE.write_text(_gallery_page(paths, drawn_by))
        say(f"wrote {GALLERY_PAGE}")
    return written


def _gallery_page(paths, drawn_by) -> str:
    """The gallery page; each picture's renderer is named (once for all when one renderer drew them all)."""
    same = len(set(drawn_by)) == 1
    lines = ["# Gallery", "",
             "<!-- Written by `pdemfem render --gallery`, which runs every examples/*.yaml and draws its last "
             "output step. -->", "",
             "The last output step of every example in `examples/`, as `pdemfem render --gallery` draws it",
             "(particles coloured by speed, solids by the magnitude of their displacement, walls translucent;",
             "with heat on, particles and solids by temperature on one scale).",
             *([f"These pictures were drawn by {drawn_by[0]}."] if same else []),
             "Run one yourself: `pdemfem run examples/<name>.yaml -o out/<name>`, then",
             "`pdemfem render out/<name> --scene examples/<name>.yaml`, or open the XDMF files in ParaView.",
             "`pdemfem render` draws with ParaView (pvpython) when it is installed and with matplotlib",
             "otherwise (`--renderer auto|paraview|matplotlib`; docs/output.md).", ""]
    for path, used in zip(paths, drawn_by):
        lines += [f"## {path.stem}", "", _first_comment(path) + ("" if same else f" (Drawn by {used}.)"), "",
                  f"![{path.stem}](img/gallery/{path.stem}.png)", "",
                  f"Scene: [examples/{path.name}](../examples/{path.name})", ""]
    return "\n".join(lines)

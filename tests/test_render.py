"""`pdemfem render`: a picture of a run's last output step (matplotlib, or ParaView's pvpython when
installed), and the committed gallery."""
from __future__ import annotations

import copy
import os
import shutil
import sys
from pathlib import Path

import numpy as np
import pytest

from pdemfem import Simulation, cli
from pdemfem.render import GALLERY_DIR, GALLERY_PAGE, PICTURE_SIZE, PVPYTHON_VARIABLE, draw_output, render_output

ROOT = Path(__file__).resolve().parent.parent
PNG = b"\x89PNG\r\n\x1a\n"
# Pictures committed to the repository stay small (docs/gallery.md and the README show them).
LARGEST_PICTURE = 150_000

SCENE = {
    "time": {"end": 2.0e-5, "dt": 1.0e-6},
    "materials": {"glass": {"density": 2500, "youngs_modulus": 1.0e7, "poisson_ratio": 0.3},
                  "alu": {"density": 2700, "youngs_modulus": 7.0e10, "poisson_ratio": 0.33}},
    "particles": [{"name": "grains", "material": "glass", "radius": 0.002,
                   "insert": {"kind": "list", "positions": [[0.03, 0.01, 0.013], [0.07, 0.01, 0.013]],
                              "velocities": [[0, 0, -0.1], [0, 0, -0.1]]}}],
    "walls": [{"name": "drum", "kind": "cylinder", "axis": {"point": [0.05, 0.01, 0.0], "direction": [1, 0, 0]},
               "radius": 0.05, "material": "alu"}],
    "solids": [{"name": "plate", "mesh": {"box": [[0, 0, 0], [0.1, 0.02, 0.01]], "cells": [4, 1, 1]},
                "material": "alu", "fixed": ["xmin", "xmax"], "contact": ["zmax"]}],
    "output": {"every": 1.0e-5},
}


@pytest.fixture(scope="module")
def tiny_run(tmp_path_factory):
    """(scene file, output directory) of a 20-step run: two grains over a plate in a drum."""
    import yaml

    directory = tmp_path_factory.mktemp("tiny_run")
    scene_file = directory / "scene.yaml"
    scene_file.write_text(yaml.safe_dump(copy.deepcopy(SCENE)))
    Simulation.from_file(scene_file, output_dir=directory / "out").run(progress=False)
    return scene_file, directory / "out"


def _pixels(path: Path) -> np.ndarray:
    """The picture as an (height, width, 3) float array in [0, 1]."""
    from matplotlib import image

    return image.imread(path)[:, :, :3]


def _png_size(path: Path):
    header = path.read_bytes()[:24]
    assert header[:8] == PNG
    return int.from_bytes(header[16:20], "big"), int.from_bytes(header[20:24], "big")


def test_render_draws_particles_solids_and_walls(tiny_run, tmp_path):
    scene_file, out = tiny_run
    picture = render_output(out, scene=scene_file, target=tmp_path / "render.png", renderer="matplotlib")
    assert picture == tmp_path / "render.png"
    assert _png_size(picture) == PICTURE_SIZE and picture.stat().st_size < LARGEST_PICTURE
    # Without the scene: the particles and every solid series beside them.
    assert render_output(out, target=tmp_path / "bare.png", renderer="matplotlib").read_bytes()[:8] == PNG
    # The command: `pdemfem render OUTDIR --scene FILE -o PNG`.
    assert cli.main(["render", str(out), "--scene", str(scene_file), "-o", str(tmp_path / "cli.png"),
                     "--renderer", "matplotlib", "--quiet"]) == 0
    assert (tmp_path / "cli.png").read_bytes()[:8] == PNG


def test_render_without_the_scene_does_not_take_the_clump_series_for_a_solid(tiny_run, tmp_path):
    """A clump run writes clumps.h5/.xdmf beside particles.h5; without --scene, render took it for a solid series
    and stopped with a KeyError traceback."""
    _, out = tiny_run
    copy_of_run = tmp_path / "out"
    shutil.copytree(out, copy_of_run)
    # The bodies' series has the particle series' layout (pdemfem.io.particle_output): a copy stands for it.
    shutil.copy(copy_of_run / "particles.h5", copy_of_run / "clumps.h5")
    (copy_of_run / "clumps.xdmf").write_text((copy_of_run / "particles.xdmf").read_text().replace("particles.h5",
                                                                                                  "clumps.h5"))
    picture = render_output(copy_of_run, target=tmp_path / "bare.png", renderer="matplotlib")
    assert picture.read_bytes()[:8] == PNG


# An X11 build of ParaView (Debian's) needs an X display even offscreen: $DISPLAY, or Xvfb which render starts.
PARAVIEW_HAS_A_DISPLAY = (not sys.platform.startswith("linux") or bool(os.environ.get("DISPLAY"))
                          or shutil.which("Xvfb") is not None)


@pytest.mark.skipif(shutil.which("pvpython") is None or not PARAVIEW_HAS_A_DISPLAY,
                    reason="pvpython not on PATH (Debian package paraview) or no X display nor Xvfb for it")
def test_paraview_draws_the_run(tiny_run, tmp_path, capsys):
    scene_file, out = tiny_run
    picture, used = draw_output(out, scene=scene_file, target=tmp_path / "paraview.png", renderer="paraview")
    assert used.startswith("ParaView ")
    assert _png_size(picture) == PICTURE_SIZE  # the matplotlib picture's size: the gallery mixes both
    assert picture.stat().st_size < LARGEST_PICTURE
    pixels = _pixels(picture)
    background = np.all(pixels > 0.98, axis=2)  # white, up to 8-bit rounding
    # The drum (translucent grey) and the plate fill a good part of the picture, not just the title.
    assert (~background).mean() > 0.2
    # The plate is coloured by |u| (plasma) and the grains by speed (viridis): saturated pixels, which
    # neither the white background nor the grey walls and black text have.
    saturation = pixels.max(axis=2) - pixels.min(axis=2)
    assert (saturation > 0.3).mean() > 0.01
    # The command, with auto choosing ParaView because pvpython is on PATH.
    assert cli.main(["render", str(out), "--scene", str(scene_file), "-o", str(tmp_path / "auto.png")]) == 0
    assert _png_size(tmp_path / "auto.png") == PICTURE_SIZE
    assert "ParaView could not" not in capsys.readouterr().err


@pytest.mark.skipif(shutil.which("pvpython") is None or PARAVIEW_HAS_A_DISPLAY,
                    reason="needs pvpython on a Linux host without an X display and without Xvfb")
def test_paraview_without_a_display_names_the_fix_and_auto_falls_back_to_matplotlib(tiny_run, tmp_path, capsys):
    scene_file, out = tiny_run
    assert cli.main(["render", str(out), "-o", str(tmp_path / "x.png"), "--renderer", "paraview"]) == 2
    assert "install Xvfb (apt-get install xvfb)" in capsys.readouterr().err
    assert not (tmp_path / "x.png").exists()
    # auto: ParaView is tried, fails, and matplotlib draws the picture with a warning naming the reason.
    assert cli.main(["render", str(out), "--scene", str(scene_file), "-o", str(tmp_path / "auto.png")]) == 0
    assert _png_size(tmp_path / "auto.png") == PICTURE_SIZE
    assert "ParaView could not draw auto.png" in capsys.readouterr().err


def test_renderer_paraview_without_pvpython_names_the_fix(tiny_run, tmp_path, monkeypatch, capsys):
    scene_file, out = tiny_run
    monkeypatch.setenv("PATH", str(tmp_path))  # no pvpython on it
    monkeypatch.delenv(PVPYTHON_VARIABLE, raising=False)
    assert cli.main(["render", str(out), "-o", str(tmp_path / "none.png"), "--renderer", "paraview"]) == 2
    error = capsys.readouterr().err
    assert "pvpython (ParaView's Python) is not on PATH" in error
    assert "apt-get install paraview" in error and "--pvpython PATH" in error and "--renderer matplotlib" in error
    assert not (tmp_path / "none.png").exists()
    # A pvpython that is given but is no executable is named, whatever the renderer asked for.
    assert cli.main(["render", str(out), "--pvpython", str(tmp_path / "missing"), "--quiet"]) == 2
    assert "--pvpython" in capsys.readouterr().err
    monkeypatch.setenv(PVPYTHON_VARIABLE, str(tmp_path / "missing"))
    assert cli.main(["render", str(out), "--quiet"]) == 2
    assert PVPYTHON_VARIABLE in capsys.readouterr().err
    assert cli.main(["render", str(out), "--renderer", "povray"]) == 2
    assert "unknown renderer 'povray'" in capsys.readouterr().err
    # auto without pvpython draws with matplotlib, saying nothing about ParaView.
    monkeypatch.delenv(PVPYTHON_VARIABLE)
    assert cli.main(["render", str(out), "-o", str(tmp_path / "auto.png"), "--quiet"]) == 0
    assert _png_size(tmp_path / "auto.png") == PICTURE_SIZE and capsys.readouterr().err == ""


def test_a_failing_pvpython_falls_back_to_matplotlib_with_its_reason(tiny_run, tmp_path, capsys):
    scene_file, out = tiny_run
    broken = tmp_path / "pvpython"
    broken.write_text("#!/bin/sh\necho 'Traceback (most recent call last):' >&2\n"
                      "echo 'ImportError: libvtkRendering.so: cannot open shared object file' >&2\nexit 3\n")
    broken.chmod(0o755)
    assert cli.main(["render", str(out), "-o", str(tmp_path / "fallback.png"), "--pvpython", str(broken),
                     "--quiet"]) == 0
    error = capsys.readouterr().err.strip()
    assert len(error.splitlines()) == 1  # the reason in one line, not pvpython's whole output
    assert "pvpython exited with status 3: ImportError: libvtkRendering.so" in error
    assert error.endswith("drawing it with matplotlib")
    assert _png_size(tmp_path / "fallback.png") == PICTURE_SIZE
    # Asked for ParaView explicitly, the failure is the error (exit 2), not a silent matplotlib picture.
    assert cli.main(["render", str(out), "-o", str(tmp_path / "failed.png"), "--pvpython", str(broken),
                     "--renderer", "paraview"]) == 2
    assert "pvpython exited with status 3" in capsys.readouterr().err
    assert not (tmp_path / "failed.png").exists()


def test_render_without_an_output_directory_is_a_clear_error(tmp_path, capsys):
    assert cli.main(["render", str(tmp_path / "missing")]) == 2
    assert "no such output directory" in capsys.readouterr().err
    assert cli.main(["render"]) == 2
    assert "no output directory given" in capsys.readouterr().err


@pytest.mark.parametrize("example", sorted((ROOT / "examples").glob("*.yaml")), ids=lambda path: path.name)
def test_gallery_shows_every_example(example):
    """docs/gallery.md is written by `pdemfem render --gallery`: a new example needs its picture."""
    picture = GALLERY_DIR / f"{example.stem}.png"
    assert picture.is_file(), f"no picture of {example.name}: run `pdemfem render --gallery`"
    assert picture.read_bytes()[:8] == PNG and picture.stat().st_size < LARGEST_PICTURE
    assert f"(img/gallery/{example.stem}.png)" in GALLERY_PAGE.read_text()
    assert f"docs/img/gallery/{example.stem}.png" in (ROOT / "README.md").read_text()


def test_gallery_page_names_the_renderer():
    """The committed pictures may come from either renderer: the page says which drew them."""
    page = GALLERY_PAGE.read_text()
    assert "These pictures were drawn by ParaView " in page or "These pictures were drawn by matplotlib " in page


def test_render_after_plot_in_one_process_draws_in_3d():
    """`plot` imported pyplot first; where a system matplotlib's toolkit shadowed this one's (Debian's
    python3-matplotlib beside the environment's), pyplot's registration of the '3d' projection failed (a
    warning only) and a later `render` in the same process raised "Unknown projection '3d'".  A fresh process
    imports pyplot the plain way first, then asks render for its axes."""
    import subprocess

    program = ("import warnings; warnings.simplefilter('ignore')\n"
               "import matplotlib; matplotlib.use('Agg')\n"
               "from matplotlib import pyplot\n"
               "from pdemfem.render import _pyplot\n"
               "pyplot, _ = _pyplot()\n"
               "print(pyplot.figure().add_subplot(projection='3d').name)\n")
    ran = subprocess.run([sys.executable, "-c", program], capture_output=True, text=True, timeout=120)
    assert ran.returncode == 0 and ran.stdout.strip() == "3d", ran.stderr[-2000:]

"""`pdemfem render`: a picture of a run's last output step, and the committed gallery."""
from __future__ import annotations

import copy
from pathlib import Path

import pytest

from pdemfem import Simulation, cli
from pdemfem.render import GALLERY_DIR, GALLERY_PAGE, render_output

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


def test_render_draws_particles_solids_and_walls(tmp_path):
    scene_file = tmp_path / "scene.yaml"
    import yaml

    scene_file.write_text(yaml.safe_dump(copy.deepcopy(SCENE)))
    Simulation.from_file(scene_file, output_dir=tmp_path / "out").run(progress=False)
    picture = render_output(tmp_path / "out", scene=scene_file)
    assert picture == tmp_path / "out" / "render.png"
    assert picture.read_bytes()[:8] == PNG and picture.stat().st_size < LARGEST_PICTURE
    # Without the scene: the particles and every solid series beside them.
    assert render_output(tmp_path / "out", target=tmp_path / "bare.png").read_bytes()[:8] == PNG
    # The command: `pdemfem render OUTDIR --scene FILE -o PNG`.
    assert cli.main(["render", str(tmp_path / "out"), "--scene", str(scene_file), "-o", str(tmp_path / "cli.png"),
                     "--quiet"]) == 0
    assert (tmp_path / "cli.png").read_bytes()[:8] == PNG


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

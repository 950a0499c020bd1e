"""Particles leaving the domain box: removed, counted, and their energy booked (lost_energy), so the
bookkeeping total stays flat across the removals."""
from __future__ import annotations

import collections
import shutil
import subprocess
import sys
import xml.etree.ElementTree as ET

import h5py
import numpy as np
import pytest

from mpi_harness import paraview_views
from pdemfem import Simulation
from pdemfem.monitor import total_energy
from pdemfem.plot import read_history


def falling_scene(bottom: float) -> dict:
    """25 spheres, spinning, thrown sideways and falling freely out through the box's floor at z = 0 (no walls,
    no contacts): every energy term but the removals' is exact, so the total is flat to round-off."""
    grid = np.arange(5) * 0.004
    positions = np.array([[x, y, bottom + 0.5 * x] for x in grid for y in grid])
    return {"time": {"end": 0.2, "dt": 1.0e-5},
            "gravity": [0, 0, -9.81],
            "materials": {"glass": {"density": 2500, "youngs_modulus": 5.0e6, "poisson_ratio": 0.3}},
            "particles": [{"name": "grains", "material": "glass", "radius": 0.001,
                           "insert": {"kind": "list", "positions": positions.tolist(),
                                      "velocities": [[0.3, 0.0, 0.01 * k] for k in range(25)],
                                      "angular_velocities": [[0.0, 50.0, 10.0 * k] for k in range(25)]}}],
            "domain": {"box": [[-1, -1, 0.0], [1, 1, 1]]},
            "output": {"every": 0.01, "particles": []}}


@pytest.mark.parametrize("bottom", [0.001, 0.05])
def test_the_energy_of_removed_particles_is_booked(tmp_path, bottom):
    """Before, the total fell by all the removed particles' energy (-100 % of it in a tester's scene) or, with
    the potential negative below the origin, rose: the run monitor restarted its comparison and said nothing."""
    scene = falling_scene(bottom)
    sim = Simulation.from_dict(scene, output_dir=tmp_path)
    sim.run(progress=False)
    history = read_history(tmp_path / "history.csv")
    assert history["lost_particles"][-1] == 25 and history["particles"][-1] == 0
    total = total_energy(collections.defaultdict(float, history))  # the monitor's sum, lost_energy included
    # Free flight under gravity: velocity Verlet keeps K + P to round-off, and each particle's energy moves
    # whole from K + R + P to lost_energy.  Round-off of sums of 25 terms of ~1e-4 J: 1e-12 of the scale.
    scale = np.abs(history["kinetic_energy"]).max() + np.abs(history["potential_energy"]).max()
    assert np.abs(total - total[0]).max() < 1e-12 * scale
    assert abs(history["lost_energy"][-1]) > 0.1 * scale  # the books moved: the test above is not 0 == 0


def test_the_energy_an_outlet_takes_is_booked_at_the_end_of_the_step(tmp_path):
    """The same spheres taken by a plane outlet instead: stream_energy books what they carry out.  Booked with
    the half step's velocities (a rebuild comes between the drift and the forces), the total moved by 1.4e-4
    of their energy; with the second half kick completed it is flat to round-off."""
    scene = falling_scene(0.001)
    del scene["domain"]
    scene["outlets"] = [{"name": "chute", "kind": "plane", "point": [0, 0, 0], "normal": [0, 0, -1]}]
    Simulation.from_dict(scene, output_dir=tmp_path).run(progress=False)
    history = read_history(tmp_path / "history.csv")
    assert history["particles_out"][-1] == 25 and history["particles"][-1] == 0
    total = total_energy(collections.defaultdict(float, history))  # the monitor's sum, stream_energy included
    scale = np.abs(history["kinetic_energy"]).max() + np.abs(history["potential_energy"]).max()
    assert np.abs(total - total[0]).max() < 1e-12 * scale  # as above
    assert abs(history["stream_energy"][-1]) > 0.1 * scale


def test_steps_without_particles_stay_in_the_particle_series(tmp_path):
    """Once every particle has left, particles.xdmf left the empty steps out: ParaView's time range ended at the
    last step with particles, and beside a solid's series the particles hung there to the end of the run.  Each
    step is indexed now, an empty one as a grid with its time alone."""
    scene = falling_scene(0.001)
    scene["output"] = {"every": 0.02, "particles": ["positions", "radii", "velocities"]}
    Simulation.from_dict(scene, output_dir=tmp_path).run(progress=False)
    history = read_history(tmp_path / "history.csv")
    with h5py.File(tmp_path / "particles.h5", "r") as handle:
        counts = [int(handle[name].attrs["count"]) for name in sorted(handle) if name.startswith("step_")]
    assert counts[-1] == 0 and counts[0] == 25
    grids = ET.parse(tmp_path / "particles.xdmf").getroot().find("Domain/Grid").findall("Grid")
    np.testing.assert_array_equal([float(grid.find("Time").get("Value")) for grid in grids], history["time"])
    pvpython = shutil.which("pvpython")
    if pvpython is None:
        return  # ParaView itself (Debian package paraview) reads the series below when installed
    (seen,) = paraview_views(pvpython, tmp_path / "particles.xdmf")
    assert seen["points"] == counts
    np.testing.assert_allclose(seen["times"], history["time"], rtol=1e-15)


DUMBBELL = """\
time: {end: 0.004, dt: 1.0e-5}
gravity: [0, 0, -9.81]
domain: {box: [[-0.05, -0.05, 0.0], [0.05, 0.05, 0.05]]}
materials:
  stone: {density: 2600, youngs_modulus: 5.0e6, poisson_ratio: 0.25}
interactions:
  default: {model: hertz_mindlin, restitution: 0.4, friction: 0.5}
particles:
  - name: dumbbells
    material: stone
    clump:
      spheres: [{position: [-0.001, 0, 0], radius: 0.0015}, {position: [0.001, 0, 0], radius: 0.0015}]
    insert:
      kind: list
      positions: [[0, 0, 0.0020]]
      velocities: [[0, 0, -1.0]]
      orientations: [[1, 0, 0, 0]]
output: {dir: out, every: 0.0001, particles: []}
checkpoint: {every: 0.002, keep: 5}
"""


@pytest.mark.mpi
def test_a_clump_leaving_right_after_a_restart_is_booked_once(tmp_path):
    """A checkpoint is read into every rank (the bodies replicated, the members shared out by id) and the
    members migrate to their body's rank at the next rebuild, after the removals: a dumbbell whose two members
    sat on two ranks there, leaving the box at that rebuild, was booked by both (lost_energy 7.07e-5 J against
    3.54e-5 J uninterrupted, on 2 ranks)."""
    from pdemfem.runtime import mpiexec_command, process_environment

    (tmp_path / "scene.yaml").write_text(DUMBBELL)

    def run(out, *extra):
        command = mpiexec_command(2, [sys.executable, "-m", "pdemfem.cli", "run", str(tmp_path / "scene.yaml"),
                                      "-o", str(out), "--quiet", *extra])
        completed = subprocess.run(command, env=process_environment(), capture_output=True, text=True, timeout=300)
        assert completed.returncode == 0, completed.stderr[-3000:]
        return read_history(out / "history.csv")

    whole = run(tmp_path / "whole")
    shutil.copytree(tmp_path / "whole", tmp_path / "again")
    # At step 200 both members are just below z = 0, not yet removed (that is the next rebuild's work).
    again = run(tmp_path / "again", "--restart", str(tmp_path / "again" / "checkpoints" / "checkpoint_000000000200.h5"))
    assert whole["lost_particles"][-1] == 2 and again["lost_particles"][-1] == 2
    assert whole["lost_energy"][-1] > 0
    # The same energy whatever the ranks hold: the sums over the ranks may add in another order (round-off).
    assert again["lost_energy"][-1] == pytest.approx(whole["lost_energy"][-1], rel=1e-12)


def test_a_periodic_scene_without_particles_runs_as_check_accepts_it(tmp_path, capsys):
    """A solid and a floor alone (the particles of a scene taken out to look at the solid) in a periodic domain:
    check said 'scene OK' and run refused it, comparing the period with a cutoff made of no particle's
    diameter and a default skin (0.3 m)."""
    import yaml

    from pdemfem import cli

    scene = {"time": {"end": 2e-4, "dt": "auto"}, "gravity": [0, 0, -9.81],
             "materials": {"glass": {"density": 2500, "youngs_modulus": 1.0e7, "poisson_ratio": 0.3}},
             "interactions": {"default": {"restitution": 0.5, "friction": 0.5}},
             "particles": [],
             "walls": [{"name": "floor", "kind": "plane", "point": [0, 0, 0], "normal": [0, 0, 1],
                        "material": "glass"}],
             "solids": [{"name": "plate", "mesh": {"box": [[0, 0, -0.004], [0.01, 0.01, -0.001]], "cells": [4, 4, 1]},
                         "material": "glass", "fixed": ["zmin"], "contact": ["zmax"]}],
             "domain": {"box": [[-0.01, -0.01, -0.01], [0.02, 0.02, 0.05]], "periodic": ["y"]},
             "output": {"particles": [], "solids": []}}
    path = tmp_path / "scene.yaml"
    path.write_text(yaml.safe_dump(scene))
    assert cli.main(["check", str(path)]) == 0
    code = cli.main(["run", str(path), "--quiet", "-o", str(tmp_path / "out")])
    assert code == 0, capsys.readouterr().err

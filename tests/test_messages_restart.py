"""Restart messages and the final checkpoint: a finished run with checkpoint.every leaves one at its end (so
raising time.end extends it), one without leaves none; a restart refused for a changed dt gives the exact time.dt
to set, and a changed particle count is refused even with --force (the checkpoint's particles would be used).
"""
from __future__ import annotations

import math

import h5py
import pytest

from pdemfem import cli

# 20 grains on a floor, a checkpoint every 0.0015 s (the end, 0.002 s, is not a multiple).
SCENE = """\
time: {end: 0.002, dt: auto, dt_factor: 0.1}
materials:
  glass: {density: 2500, youngs_modulus: 5.0e6, poisson_ratio: 0.3}
particles:
  - name: grains
    material: glass
    radius: 0.001
    insert:
      kind: lattice
      region: {box: [[0, 0, 0], [0.01, 0.01, 0.01]]}
      count: 20
walls:
  - {name: floor, kind: plane, point: [0, 0, 0], normal: [0, 0, 1], material: glass}
output: {dir: results, every: 0.001}
checkpoint: {every: 0.0015}
"""


@pytest.fixture(scope="module")
def finished(tmp_path_factory):
    """A finished run of SCENE in its own folder."""
    folder = tmp_path_factory.mktemp("finished")
    (folder / "scene.yaml").write_text(SCENE)
    assert cli.main(["run", str(folder / "scene.yaml"), "--quiet"]) == 0
    return folder


def run(capsys, *argv):
    code = cli.main([str(a) for a in argv])
    out, err = capsys.readouterr()
    return code, out, err


def test_a_finished_run_leaves_a_final_checkpoint_that_a_later_end_extends(finished, tmp_path, capsys):
    checkpoints = finished / "results" / "checkpoints"
    written = sorted(checkpoints.glob("checkpoint_*.h5"))
    assert len(written) == 2 and (checkpoints / "latest.h5").is_file()  # at 0.0015 s and at the end
    with h5py.File(checkpoints / "latest.h5", "r") as handle:
        dt, step = float(handle.attrs["dt"]), int(handle.attrs["step"])
    assert step == math.ceil(0.002 / dt - 1e-9)  # the last step of the run (Simulation.run)
    # Extending the run: a later time.end, no --force.
    longer = tmp_path / "longer.yaml"
    longer.write_text(SCENE.replace("end: 0.002", "end: 0.003"))
    code, _, err = run(capsys, "run", longer, "-o", tmp_path / "more", "--quiet", "--restart", checkpoints / "latest.h5")
    assert code == 0, err
    assert (tmp_path / "more" / "checkpoints" / "latest.h5").is_file()
    # Without a checkpoint section a finished run leaves none (its directory holds no checkpoints to protect).
    plain = tmp_path / "plain.yaml"
    plain.write_text(SCENE.replace("checkpoint: {every: 0.0015}\n", ""))
    code, _, err = run(capsys, "run", plain, "-o", tmp_path / "plain", "--quiet")
    assert code == 0, err
    assert not list((tmp_path / "plain").glob("checkpoints/*.h5"))


def test_changed_dt_auto_gives_the_exact_time_dt_to_set(finished, tmp_path, capsys):
    latest = finished / "results" / "checkpoints" / "latest.h5"
    with h5py.File(latest, "r") as handle:
        stored = float(handle.attrs["dt"])
    stiffer = tmp_path / "stiffer.yaml"
    stiffer.write_text(SCENE.replace("end: 0.002", "end: 0.003").replace("youngs_modulus: 5.0e6",
                                                                         "youngs_modulus: 6.0e6"))
    code, _, err = run(capsys, "run", stiffer, "-o", tmp_path / "o", "--quiet", "--restart", latest, "--force")
    assert code == 2, err
    assert err.count("error:") == 1 and "Traceback" not in err
    assert f"fix: set time.dt: {stored!r} in the scene" in err, err
    assert not (tmp_path / "o").exists()
    # Following the fix continues the run.
    stiffer.write_text(stiffer.read_text().replace("dt: auto", f"dt: {stored!r}"))
    code, _, err = run(capsys, "run", stiffer, "-o", tmp_path / "o", "--quiet", "--restart", latest, "--force")
    assert code == 0, err


def test_changed_particle_count_is_refused_even_with_force(finished, tmp_path, capsys):
    latest = finished / "results" / "checkpoints" / "latest.h5"
    fewer = tmp_path / "fewer.yaml"
    fewer.write_text(SCENE.replace("end: 0.002", "end: 0.003").replace("count: 20", "count: 18"))
    code, _, err = run(capsys, "run", fewer, "-o", tmp_path / "o", "--quiet", "--restart", latest, "--force")
    assert code == 2, err
    assert err.count("error:") == 1 and "Traceback" not in err
    assert "holds the 20 particles" in err and "this scene inserts 18" in err, err
    assert "particles[0].insert.count: 20 -> 18" in err and "refused even with --force" in err
    assert not (tmp_path / "o").exists()


def test_another_scenes_checkpoint_is_refused_first_for_what_no_edit_fixes(finished, tmp_path, capsys):
    """--force from another scene's checkpoint: the refusals time.end and dt can lift came first, so a user
    raised time.end, then set dt, and only then learnt that the particles were another scene's."""
    latest = finished / "results" / "checkpoints" / "latest.h5"
    other = tmp_path / "other.yaml"
    # At the checkpoint's time.end, another step and 18 grains: the particle count is named first.
    other.write_text(SCENE.replace("count: 20", "count: 18").replace("dt: auto, dt_factor: 0.1", "dt: 1.0e-6"))
    code, _, err = run(capsys, "run", other, "-o", tmp_path / "o", "--quiet", "--restart", latest, "--force")
    assert code == 2, err
    assert "holds the 20 particles" in err and "nothing left to run" not in err and "time.dt" not in err, err
    # Without --force as well: the physics change came first and advised "add --force", which cannot help.
    code, _, err = run(capsys, "run", other, "-o", tmp_path / "o", "--quiet", "--restart", latest)
    assert code == 2 and "holds the 20 particles" in err and "add --force" not in err, err


@pytest.mark.parametrize("change", ["moved", "added"])
def test_changed_walls_are_refused_even_with_force(finished, tmp_path, capsys, change):
    """The walls' positions and motion are stored state, restored by their place in the list: a moved floor
    would silently stay where the checkpoint had it, and a reordered list would pair one wall's normal with
    another's point (every particle behind it at the first step)."""
    latest = finished / "results" / "checkpoints" / "latest.h5"
    floor = "  - {name: floor, kind: plane, point: [0, 0, 0], normal: [0, 0, 1], material: glass}\n"
    changed = {"moved": floor.replace("point: [0, 0, 0]", "point: [0, 0, -0.0005]"),
               "added": "  - {name: side, kind: plane, point: [0, 0, 0], normal: [1, 0, 0], material: glass}\n" + floor}
    with h5py.File(latest, "r") as handle:
        stored = float(handle.attrs["dt"])
    scene = tmp_path / "walls.yaml"
    scene.write_text(SCENE.replace("end: 0.002", "end: 0.003").replace(floor, changed[change])
                     .replace("dt: auto", f"dt: {stored!r}"))
    code, _, err = run(capsys, "run", scene, "-o", tmp_path / "o", "--quiet", "--restart", latest, "--force")
    assert code == 2, err
    assert err.count("error:") == 1 and "Traceback" not in err
    assert "was written with other walls (walls" in err and "refused even with --force" in err, err
    assert not (tmp_path / "o").exists()


def test_a_changed_contact_history_width_is_refused_even_with_force(finished, tmp_path, capsys):
    latest = finished / "results" / "checkpoints" / "latest.h5"
    frictionless = tmp_path / "frictionless.yaml"
    frictionless.write_text(SCENE.replace("end: 0.002", "end: 0.003")
                            + "interactions:\n  default: {friction: 0.0}\n")
    code, _, err = run(capsys, "run", frictionless, "-o", tmp_path / "o", "--quiet", "--restart", latest, "--force")
    assert code == 2, err
    assert err.count("error:") == 1 and "Traceback" not in err
    assert "its contacts store 7 history columns each, this scene's contact laws keep 0" in err, err
    assert not (tmp_path / "o").exists()


def test_a_changed_particle_density_is_named_as_taking_no_effect_on_the_particles(finished, tmp_path, capsys, caplog):
    latest = finished / "results" / "checkpoints" / "latest.h5"
    with h5py.File(latest, "r") as handle:
        stored = float(handle.attrs["dt"])
    denser = tmp_path / "denser.yaml"
    denser.write_text(SCENE.replace("end: 0.002", "end: 0.003").replace("density: 2500", "density: 5000")
                      .replace("dt: auto", f"dt: {stored!r}"))
    code, _, err = run(capsys, "run", denser, "-o", tmp_path / "o", "--quiet", "--restart", latest, "--force")
    assert code == 0, err
    assert "take no effect on them: materials.glass.density: 2500.0 -> 5000.0" in caplog.text, caplog.text


def test_a_forced_branch_does_not_replace_the_later_checkpoints_of_the_run_it_started_from(finished, tmp_path, capsys):
    checkpoints = finished / "results" / "checkpoints"
    first, last = sorted(checkpoints.glob("checkpoint_*.h5"))
    before = last.read_bytes()
    with h5py.File(first, "r") as handle:
        stored = float(handle.attrs["dt"])
    shared = f"checkpoint: {{every: 0.0015, dir: {checkpoints}}}\n"
    branch = tmp_path / "branch.yaml"
    branch.write_text(SCENE.replace("checkpoint: {every: 0.0015}\n", shared).replace("dt: auto", f"dt: {stored!r}")
                      + "interactions:\n  default: {restitution: 0.3}\n")
    code, _, err = run(capsys, "run", branch, "-o", tmp_path / "branch", "--quiet", "--restart", first, "--force")
    assert code == 2, err
    assert err.count("error:") == 1 and "Traceback" not in err
    assert f"holds checkpoints of later steps than the restart's ({last.name}) written with other physics" in err, err
    assert last.read_bytes() == before
    # The same physics continued elsewhere writes the same checkpoints again (a restart continues exactly).
    same = tmp_path / "same.yaml"
    same.write_text(SCENE.replace("checkpoint: {every: 0.0015}\n", shared))
    code, _, err = run(capsys, "run", same, "-o", tmp_path / "same", "--quiet", "--restart", first)
    assert code == 0, err
    assert last.read_bytes() == before


PLATE = """\
time: {end: 0.002, dt: 2.0e-5}
materials:
  glass: {density: 2500, youngs_modulus: 5.0e6, poisson_ratio: 0.3}
  alu: {density: 2700, youngs_modulus: 1.0e9, poisson_ratio: 0.33}
particles:
  - name: grains
    material: glass
    radius: 0.002
    insert: {kind: list, positions: [[0.01, 0.01, 0.0025], [0.03, 0.03, 0.0025]]}
solids:
  - name: block
    mesh: {box: [[0, 0, -0.01], [0.04, 0.04, 0]], cells: [2, 2, 1]}
    material: alu
    fixed: [zmin]
    contact: [zmax]
output: {dir: results, every: 0.001}
checkpoint: {every: 0.001}
"""


def test_another_contact_surface_is_refused_even_with_force(tmp_path, capsys):
    (tmp_path / "plate.yaml").write_text(PLATE)
    assert cli.main(["run", str(tmp_path / "plate.yaml"), "--quiet"]) == 0
    checkpoints = sorted((tmp_path / "results" / "checkpoints").glob("checkpoint_*.h5"))
    wider = tmp_path / "wider.yaml"
    wider.write_text(PLATE.replace("end: 0.002", "end: 0.003").replace("contact: [zmax]", "contact: [zmax, xmin]"))
    code, _, err = run(capsys, "run", wider, "-o", tmp_path / "o", "--quiet", "--restart", checkpoints[-1], "--force")
    assert code == 2, err
    assert err.count("error:") == 1 and "Traceback" not in err
    # 3 x 3 nodes on top; the 3 x 2 of the xmin side share its edge of 3: 12.
    assert "solid 'block': its contact surface has 9 nodes in the checkpoint, 12 in this scene" in err, err


def _write_plate_files(folder, shift=0.0, wall_shift=0.0):
    """block.vtu: the box [0, 0.04]^2 x [-0.01, 0] in six tetrahedra (x moved by `shift`); floor.stl: a square
    0.01 m below it (z moved by `wall_shift`)."""
    import meshio
    import numpy as np

    corners = np.array([[i, j, k] for k in (0, 1) for j in (0, 1) for i in (0, 1)], dtype=float)
    points = corners * [0.04, 0.04, 0.01] + [shift, 0.0, -0.01]
    tets = []
    for tet in ([0, 1, 3, 7], [0, 1, 5, 7], [0, 2, 3, 7], [0, 2, 6, 7], [0, 4, 5, 7], [0, 4, 6, 7]):
        edges = points[tet[1:]] - points[tet[0]]
        tets.append(tet if np.linalg.det(edges) > 0 else [tet[0], tet[2], tet[1], tet[3]])
    meshio.write(folder / "block.vtu", meshio.Mesh(points, [("tetra", tets)]))
    square = np.array([[-0.1, -0.1, 0], [0.1, -0.1, 0], [0.1, 0.1, 0], [-0.1, 0.1, 0]]) + [0, 0, -0.02 + wall_shift]
    meshio.write(folder / "floor.stl", meshio.Mesh(square, [("triangle", [[0, 1, 2], [0, 2, 3]])]))


def test_an_edited_mesh_file_is_refused_on_restart(tmp_path, capsys):
    """The scene hash covers the scene's text, not what its files hold: an edited solid mesh was continued
    without --force (and diverged, the message blaming dt), an edited mesh wall's new geometry silently ignored
    (its vertices come from the checkpoint).  Now a changed file is refused like a changed key; a mesh wall's
    even with --force."""
    scene = PLATE.replace("mesh: {box: [[0, 0, -0.01], [0.04, 0.04, 0]], cells: [2, 2, 1]}", "mesh: block.vtu")
    scene += "walls:\n  - {name: below, kind: mesh, file: floor.stl, material: alu}\n"
    (tmp_path / "plate.yaml").write_text(scene)
    _write_plate_files(tmp_path)
    assert cli.main(["run", str(tmp_path / "plate.yaml"), "--quiet"]) == 0
    checkpoint = sorted((tmp_path / "results" / "checkpoints").glob("checkpoint_*.h5"))[0]
    longer = tmp_path / "longer.yaml"
    longer.write_text(scene.replace("end: 0.002", "end: 0.003"))
    _write_plate_files(tmp_path, shift=1e-4)
    code, _, err = run(capsys, "run", longer, "-o", tmp_path / "a", "--quiet", "--restart", checkpoint)
    assert code == 2 and "solids[0].mesh (block.vtu)" in err and "changed since" in err and "--force" in err, err
    code, _, err = run(capsys, "run", longer, "-o", tmp_path / "b", "--quiet", "--restart", checkpoint, "--force")
    assert code == 0, err
    _write_plate_files(tmp_path, wall_shift=1e-3)
    code, _, err = run(capsys, "run", longer, "-o", tmp_path / "c", "--quiet", "--restart", checkpoint, "--force")
    assert code == 2 and "walls[0].file (floor.stl)" in err and "even with --force" in err, err
    _write_plate_files(tmp_path)  # the files as the checkpoint's run read them: accepted without --force
    code, _, err = run(capsys, "run", longer, "-o", tmp_path / "d", "--quiet", "--restart", checkpoint)
    assert code == 0, err


def test_a_contact_surface_facing_away_from_the_particles_is_named(tmp_path, capsys):
    """Contact is one-sided, from outside: a block's bottom listed under contact with the grains above it let
    them fall into the block and rest inside it, with no warning from check or run."""
    import yaml

    scene = yaml.safe_load(PLATE)
    scene["solids"][0]["contact"] = ["zmin"]
    scene["solids"][0]["fixed"] = ["xmin"]
    path = tmp_path / "away.yaml"
    path.write_text(yaml.safe_dump(scene))
    code, out, err = run(capsys, "check", path)
    assert code == 0 and "solids[0] (block): no face of its contact surface (zmin) faces where the particles" in out
    scene["solids"][0]["contact"] = ["zmax"]
    path.write_text(yaml.safe_dump(scene))
    code, out, err = run(capsys, "check", path)
    assert code == 0 and "faces where the particles" not in out

"""Scene validation, loading and derived quantities (pdemfem.scene).

Every bad-scene class must give ONE SceneError (exit code 2) whose
message names the key path and the fix.  The classes detected only when the
particles are built (overlapping list insertions, an insertion that cannot place
its count) are tested through `pdemfem check` / `pdemfem run` in test_cli.py.
"""
from __future__ import annotations

import copy
import math
from pathlib import Path

import pytest

from pdemfem.errors import SceneError
from pdemfem.scene import derived
from pdemfem.scene.loader import load_scene, output_directory, resolve_path, scene_hash

EXAMPLES = Path(__file__).resolve().parent.parent / "examples"


def base_scene() -> dict:
    return {
        "time": {"end": 0.01, "dt": "auto", "dt_factor": 0.2},
        "gravity": [0, 0, -9.81],
        "materials": {"glass": {"density": 2500, "youngs_modulus": 5.0e6, "poisson_ratio": 0.3}},
        "interactions": {"default": {"model": "hertz_mindlin", "restitution": 0.5, "friction": 0.5}},
        "particles": [
            {
                "name": "grains",
                "material": "glass",
                "radius": 0.001,
                "insert": {"kind": "lattice", "region": {"box": [[0, 0, 0], [0.05, 0.05, 0.1]]}, "count": 100},
            }
        ],
        "walls": [{"name": "floor", "kind": "plane", "point": [0, 0, 0], "normal": [0, 0, 1], "material": "glass"}],
        "output": {"dir": "out", "every": 1.0e-3},
    }


def modified(change) -> dict:
    scene = base_scene()
    change(scene)
    return scene


def scene_error(data) -> SceneError:
    with pytest.raises(SceneError) as caught:
        load_scene(data)
    return caught.value


def test_valid_scene_loads_with_defaults_and_base_dir(tmp_path):
    scene, base_dir = load_scene(base_scene(), base_dir=tmp_path)
    assert base_dir == tmp_path.resolve()
    assert scene.particles[0].insert.count == 100
    assert scene.neighbors.skin is None  # default: 0.3 * smallest radius, chosen by the engine
    assert scene.interaction("glass", "glass").restitution == 0.5


# (change, key path the message must name, fragment of the problem, fragment of the fix)
BAD_SCENES = {
    "misspelt key": (
        lambda s: s["particles"][0]["insert"].update(cuont=s["particles"][0]["insert"].pop("count")),
        "particles[0].insert.cuont", "unknown key 'cuont'", "did you mean 'count'?",
    ),
    "misspelt required key": (
        lambda s: s.update(tme=s.pop("time")),
        "tme", "unknown key 'tme' (and the required key 'time' is missing)", "rename 'tme' to 'time'",
    ),
    "unknown key": (
        lambda s: s["materials"]["glass"].update(youngs_modulos=1e6),
        "materials.glass.youngs_modulos", "unknown key", "did you mean 'youngs_modulus'?",
    ),
    "unknown top-level key": (
        lambda s: s.update(gravty=[0, 0, -9.81]),
        "gravty", "unknown key", "did you mean 'gravity'?",
    ),
    "wrong type": (
        lambda s: s["materials"]["glass"].update(youngs_modulus="stiff"),
        "materials.glass.youngs_modulus", "expected a number, got 'stiff'", "as a number",
    ),
    "wrong type (integer)": (
        lambda s: s["particles"][0]["insert"].update(count=12.5),
        "particles[0].insert.count", "expected a whole number (integer)", "as a whole number",
    ),
    "missing material": (
        lambda s: s["particles"][0].update(material="steel"),
        "particles[0].material", "unknown material 'steel'", "define it under materials",
    ),
    "missing materials section": (
        lambda s: s.pop("materials"),
        "materials", "required key 'materials' is missing", "e.g. materials: {glass: {density",
    ),
    "negative radius": (
        lambda s: s["particles"][0].update(radius=-0.001),
        "particles[0].radius", "must be > 0, got -0.001", "radius must be positive",
    ),
    "radius spread reversed": (
        lambda s: s["particles"][0].update(radius={"min": 0.002, "max": 0.001}),
        "particles[0].radius", "smaller than min", "swap them",
    ),
    "interaction with unknown material": (
        lambda s: s["interactions"].update({"glass-steel": {"restitution": 0.3}}),
        "interactions.glass-steel", "known materials", "docs/scene.md",
    ),
    "misspelt material name": (
        lambda s: s["particles"][0].update(material="glas"),
        "particles[0].material", "unknown material 'glas'", "did you mean 'glass'?",
    ),
    "wall with unknown material": (
        lambda s: s["walls"][0].update(material="rubber"),
        "walls[0].material", "unknown material 'rubber'", "define it under materials",
    ),
    "bad choice": (
        lambda s: s["interactions"]["default"].update(model="hertz"),
        "interactions.default.model", "'hertz' (text) is not a valid choice", "did you mean 'hertz_mindlin'?",
    ),
    "dt neither number nor auto": (
        lambda s: s["time"].update(dt="fast"),
        "time.dt", "expected a number or 'auto'", "time.dt",
    ),
    "short vector": (
        lambda s: s.update(gravity=[0, -9.81]),
        "gravity", "too few values", "[x, y, z]",
    ),
    # A solid's series goes to <name>.h5 / .xdmf: "particles" overwrote the particles' series without a word.
    "solid named as the particle series": (
        lambda s: s.update(solids=[{"name": "particles", "mesh": {"box": [[0, 0, -0.01], [0.05, 0.05, 0]],
                                                                  "cells": [1, 1, 1]}, "material": "glass"}]),
        "solids[0].name", "particles.h5 and particles.xdmf", "rename the solid",
    ),
    "name with a path separator": (
        lambda s: s["walls"][0].update(name="walls/floor"),
        "walls[0].name", "may hold only letters, digits", "rename it",
    ),
}


@pytest.mark.parametrize("case", sorted(BAD_SCENES))
def test_bad_scene_gives_one_error_naming_key_and_fix(case):
    change, key, problem, fix = BAD_SCENES[case]
    error = scene_error(modified(change))
    assert error.exit_code == 2
    assert len(error.problems) == 1, error.problems
    message = str(error)
    assert f"<scene dict>: {key}: " in message, message
    assert problem in message, message
    assert "fix: " in message and fix in message.split("fix: ", 1)[1], message
    assert "Traceback" not in message and "pydantic" not in message


def test_unknown_key_lists_valid_keys():
    error = scene_error(modified(lambda s: s["walls"][0].update(colour="red")))
    assert error.problems[0]["key"] == "walls[0].colour"
    # No close match: the fix lists what is valid there.
    assert "valid keys here: name, kind, material, point, normal, velocity" in error.problems[0]["fix"]


def test_several_problems_each_on_its_own_line():
    def change(scene):
        scene["materials"]["glass"]["density"] = "heavy"
        scene["particles"][0]["radius"] = -1.0
        scene["time"]["ennd"] = 1.0

    error = scene_error(modified(change))
    message = str(error)
    assert "3 problems in the scene" in message
    keys = {problem["key"] for problem in error.problems}
    assert keys == {"materials.glass.density", "particles[0].radius", "time.ennd"}
    for key in keys:
        assert sum(line.strip().startswith(f"- {key}: ") for line in message.splitlines()) == 1, message


def write(tmp_path: Path, name: str, text: str) -> Path:
    path = tmp_path / name
    path.write_text(text)
    return path


GOOD_YAML = """\
time: {end: 0.01}
materials:
  glass: {density: 2500, youngs_modulus: 5.0e6, poisson_ratio: 0.3}
particles:
  - name: grains
    material: glass
    radius: 0.001
    insert:
      kind: lattice
      region: {box: [[0, 0, 0], [0.02, 0.02, 0.02]]}
      count: 27
walls:
  - {name: floor, kind: plane, point: [0, 0, 0], normal: [0, 0, 1], material: glass}
"""


def test_file_errors_name_file_and_line(tmp_path):
    path = write(tmp_path, "scene.yaml", GOOD_YAML.replace("count: 27", "count: many"))
    error = scene_error(path)
    assert str(error).startswith(f"{path}: line 11: particles[0].insert.count: expected an integer")


def test_yaml_syntax_error_names_file_and_line(tmp_path):
    path = write(tmp_path, "broken.yaml", GOOD_YAML.replace("radius: 0.001", "radius 0.001\n    : x"))
    error = scene_error(path)
    assert str(error).startswith(f"{path}, line 8, column"), str(error)
    assert "YAML syntax error" in str(error)


def test_duplicate_yaml_key_is_an_error(tmp_path):
    path = write(tmp_path, "dup.yaml", GOOD_YAML + "time: {end: 0.02}\n")
    error = scene_error(path)
    assert "key 'time' appears twice (lines 1 and 14)" in str(error)


def test_yaml_cannot_run_code(tmp_path):
    marker = tmp_path / "pwned"
    path = write(tmp_path, "evil.yaml", f'time: !!python/object/apply:os.system ["touch {marker}"]\n')
    error = scene_error(path)
    assert "YAML tag not allowed" in str(error)
    assert not marker.exists()


def test_missing_file_and_non_mapping(tmp_path):
    assert "scene file not found" in str(scene_error(tmp_path / "nope.yaml"))
    assert "must be a mapping" in str(scene_error(write(tmp_path, "list.yaml", "- a\n- b\n")))
    assert "the scene is empty" in str(scene_error(write(tmp_path, "empty.yaml", "")))


def test_paths_resolve_relative_to_the_scene_file(tmp_path, monkeypatch):
    folder = tmp_path / "scenes"
    folder.mkdir()
    path = write(folder, "scene.yaml", GOOD_YAML + "output: {dir: results}\n")
    monkeypatch.chdir(tmp_path)
    scene, base_dir = load_scene("scenes/scene.yaml")
    assert base_dir == folder.resolve()
    assert resolve_path(base_dir, "meshes/beam.msh") == folder.resolve() / "meshes" / "beam.msh"
    assert resolve_path(base_dir, "/abs/beam.msh") == Path("/abs/beam.msh")
    assert output_directory(scene, base_dir) == folder.resolve() / "results"
    # -o on the command line is relative to the current directory.
    assert output_directory(scene, base_dir, "elsewhere") == tmp_path.resolve() / "elsewhere"
    assert path.exists()


def test_scene_hash_covers_physics_only():
    reference = scene_hash(load_scene(base_scene())[0])
    # Key order and spelled-out defaults do not matter.
    reordered = dict(reversed(list(base_scene().items())))
    reordered["neighbors"] = {"skin": None}
    assert scene_hash(load_scene(reordered)[0]) == reference
    # End time, output and checkpoint settings are not physics.
    assert scene_hash(modified(lambda s: s["time"].update(end=5.0))) == reference
    assert scene_hash(modified(lambda s: s.update(output={"dir": "x", "every": 0.5}))) == reference
    # Physics is.
    assert scene_hash(modified(lambda s: s["materials"]["glass"].update(density=2600))) != reference
    assert scene_hash(modified(lambda s: s["time"].update(dt_factor=0.1))) != reference
    assert len(reference) == 64


# --------------------------------------------------------------------------- derived quantities


def test_rayleigh_time_and_time_step():
    scene, _ = load_scene(base_scene())
    # r = 1 mm glass: G = 5e6 / 2.6, T_R = pi r sqrt(rho/G) / (0.1631*0.3 + 0.8766), by hand:
    shear = 5.0e6 / 2.6
    expected = math.pi * 1e-3 * math.sqrt(2500 / shear) / 0.92553
    assert derived.rayleigh_time(scene) == pytest.approx(expected, rel=1e-12)
    assert expected == pytest.approx(1.2239e-4, rel=1e-4)
    # dt auto: dt_factor (0.2) x T_R, or less where a contact at the impact speed needs it.
    limits = [limit for limit, _ in derived.contact_step_limits(scene, derived.expected_impact_speed(scene))]
    assert limits and min(limits) < 0.2 * expected  # this scene's falling grains need the contact limit
    assert derived.time_step(scene) == pytest.approx(min(limits), rel=1e-12)
    at_rest, _ = load_scene(modified(lambda s: s.update(gravity=[0, 0, 0])))
    assert derived.time_step(at_rest) == pytest.approx(0.2 * expected, rel=1e-12)  # no impacts: T_R alone
    # A spread uses the smallest radius; an explicit dt is taken as given.
    spread, _ = load_scene(modified(lambda s: s["particles"][0].update(radius={"min": 5e-4, "max": 1e-3})))
    assert derived.rayleigh_time(spread) == pytest.approx(0.5 * expected, rel=1e-12)
    fixed, _ = load_scene(modified(lambda s: s["time"].update(dt=1e-6)))
    assert derived.time_step(fixed) == 1e-6


def test_an_end_shorter_than_one_step_of_dt_auto_is_refused_as_an_explicit_dt_is():
    """time.end 1e-9 s with dt auto: the run took one whole step (1.4e-5 s, 13,946 x the end) and wrote it as the
    end; an explicit dt above end was refused when the scene was read."""
    scene, _ = load_scene(base_scene())
    dt = derived.time_step(scene)
    short, _ = load_scene(modified(lambda s: s["time"].update(end=0.5 * dt)))
    with pytest.raises(SceneError, match="time.end") as refused:
        derived.time_step(short)
    assert f"raise time.end to at least {dt:.3g} s" in str(refused.value)
    exact, _ = load_scene(modified(lambda s: s["time"].update(end=dt)))
    assert derived.time_step(exact) == dt  # one whole step fits


def test_auto_dt_without_particles_is_a_scene_error():
    scene, _ = load_scene(modified(lambda s: s.update(particles=[])))
    with pytest.raises(SceneError, match="time.dt"):
        derived.time_step(scene)


def test_expected_impact_speed_rule():
    def falling(scene):
        scene["particles"][0]["insert"]["velocity"] = [0, 0, -1.0]
        scene["walls"][0]["point"] = [0, 0, -0.02]  # floor 2 cm below the region bottom

    scene, _ = load_scene(modified(falling))
    # The highest particle's lowest point starts at the region top minus a diameter (0.098)
    # and falls to the floor at z = -0.02: h = 0.118.
    assert derived.fall_height(scene) == pytest.approx(0.118)
    assert derived.expected_impact_speed(scene) == pytest.approx(1.0 + math.sqrt(2 * 9.81 * 0.118))
    # A tilted floor counts where the particles are: the plane z = -0.1 x through the origin
    # lies at z = -0.0049 under the last column of centres (x = 0.049), so that particle falls 0.1029.
    tilted, _ = load_scene(modified(lambda s: s["walls"][0].update(normal=[0.1, 0, 1])))
    assert derived.fall_height(tilted) == pytest.approx(0.1029, rel=1e-9)
    # Without an upward-facing wall the particles only meet each other: the region's span less a diameter.
    free, _ = load_scene(modified(lambda s: s.update(walls=[])))
    assert derived.fall_height(free) == pytest.approx(0.098)
    # A given value wins.
    given, _ = load_scene(modified(lambda s: s["time"].update(expected_impact_speed=3.0)))
    assert derived.expected_impact_speed(given) == 3.0


def test_a_solids_contact_surface_catches_falling_particles_in_the_fall_height():
    """A sphere dropped 0.3 m onto a block solid's top (its contact group): dt auto took the drop to the lowest
    starting point (0, one sphere) and an 8x too long step (restitution -5.9 %).  The drop to a box mesh's
    contact face counts like a floor's; a face that is not a contact group, or a box beside the sphere, does
    not; a solid meshed from a file cannot be seen before its mesh is read, so check says so."""
    block = {"name": "plate", "mesh": {"box": [[-0.05, -0.05, -0.02], [0.05, 0.05, 0.0]], "cells": [2, 2, 1]},
             "material": "glass", "fixed": ["zmin"], "contact": ["zmax"]}

    def dropped(**solid):
        def change(scene):
            scene["walls"] = []
            scene["particles"][0]["insert"] = {"kind": "list", "positions": [[0.01, 0.0, 0.301]]}
            scene["solids"] = [dict(block, **solid)]
        return load_scene(modified(change))[0]

    on_top = dropped()
    assert derived.fall_height(on_top) == pytest.approx(0.3, rel=1e-12)  # centre 0.301 minus r = 1 mm
    assert derived.expected_impact_speed(on_top) == pytest.approx(math.sqrt(2 * 9.81 * 0.3), rel=1e-12)
    assert derived.fall_height(dropped(contact=["xmin"])) == 0.0  # enters through a face it passes
    beside = dropped(mesh={"box": [[0.02, -0.05, -0.02], [0.1, 0.05, 0.0]], "cells": [2, 2, 1]})
    assert derived.fall_height(beside) == 0.0
    assert not [w for w in derived.warnings(on_top) if "cannot see the contact surfaces" in w]
    bridge = Path(__file__).resolve().parent.parent / "examples" / "meshes" / "bridge.msh"
    from_file = dropped(mesh=str(bridge), fixed=["abutments"], contact=["deck"])
    assert derived.fall_height(from_file) == 0.0
    seen = [w for w in derived.warnings(from_file) if "cannot see the contact surfaces" in w]
    assert seen and "plate" in seen[0] and "time.expected_impact_speed" in seen[0], seen


def test_impact_speed_of_particles_moving_towards_each_other():
    def head_on(scene):
        scene["gravity"] = [0, 0, 0]
        scene["particles"][0]["insert"] = {
            "kind": "list", "positions": [[0, 0, 0.5], [0.01, 0, 0.5]], "velocities": [[0.5, 0, 0], [-0.5, 0, 0]],
        }

    scene, _ = load_scene(modified(head_on))
    assert derived.expected_impact_speed(scene) == pytest.approx(1.0)  # closing speed, not 0.5
    # A listed particle resting on the floor does not "fall" its own radius.
    resting, _ = load_scene(modified(lambda s: s["particles"][0].update(
        insert={"kind": "list", "positions": [[0, 0, 0.001]], "velocities": [[0.3, 0, 0]]})))
    assert derived.fall_height(resting) == 0.0
    assert derived.expected_impact_speed(resting) == pytest.approx(0.3)


def test_hertz_contact_duration_matches_the_formula():
    def two_materials(scene):
        scene["materials"]["steel"] = {"density": 7800, "youngs_modulus": 2.0e11, "poisson_ratio": 0.29}
        scene["walls"][0]["material"] = "steel"

    scene, _ = load_scene(modified(two_materials))
    r, rho, E, nu, speed = 1e-3, 2500.0, 5.0e6, 0.3, 2.0
    mass = 4.0 / 3.0 * math.pi * r**3 * rho
    # Two equal glass spheres: m* = m/2, R* = r/2, E* = E / (2 (1 - nu^2)).
    e_pair = E / (2 * (1 - nu**2))
    pair = 2.868 * ((mass / 2) ** 2 / (r / 2 * e_pair**2 * speed)) ** 0.2
    # Glass on a flat steel wall: m* = m, R* = r.
    e_wall = 1.0 / ((1 - nu**2) / E + (1 - 0.29**2) / 2.0e11)
    wall = 2.868 * (mass**2 / (r * e_wall**2 * speed)) ** 0.2
    durations = derived.hertz_contact_duration(scene, speed)
    assert durations.particle_particle == pytest.approx(pair, rel=1e-12)
    assert durations.particle_wall == pytest.approx(wall, rel=1e-12)
    assert durations.shortest == min(pair, wall)
    # Hertz: t_c ~ v^(-1/5).
    slower = derived.hertz_contact_duration(scene, speed / 32.0)
    assert slower.particle_particle == pytest.approx(2.0 * pair, rel=1e-12)


def test_linear_contact_duration_uses_the_stiffness():
    scene, _ = load_scene(modified(
        lambda s: s["interactions"].update(default={"model": "linear_spring_dashpot", "normal_stiffness": 1.0e3})
    ))
    mass = 4.0 / 3.0 * math.pi * 1e-9 * 2500.0
    durations = derived.contact_duration(scene, 1.0)
    assert durations.particle_particle == pytest.approx(math.pi * math.sqrt(mass / 2 / 1.0e3), rel=1e-12)
    assert durations.particle_wall == pytest.approx(math.pi * math.sqrt(mass / 1.0e3), rel=1e-12)


def test_counts_and_memory_estimate():
    def two_groups(scene):
        scene["particles"].append({
            "name": "pair", "material": "glass", "radius": 0.001,
            "insert": {"kind": "list", "positions": [[0.1, 0.1, 0.1], [0.2, 0.2, 0.2]]},
        })

    scene, _ = load_scene(modified(two_groups))
    assert derived.group_counts(scene) == [100, 2]
    assert derived.particle_count(scene) == 102
    # Friction (the default): 7 history columns per list entry, 1.4 x (136 + 8 x (12 + 56) + 8) = 963 B.
    assert derived.contact_history_columns(scene) == 7
    assert derived.memory_estimate_bytes(scene) == 102 * derived.bytes_per_particle(7) == 102 * 960


def test_warnings_flag_a_coarse_step():
    # dt = 2.4e-5 s (0.2 T_R) against a ~2e-4 s contact at ~1.4 m/s: fewer than 30 steps per contact.
    scene, _ = load_scene(modified(lambda s: s["time"].update(dt=2.4e-5)))
    assert any("steps per particle-particle contact" in warning for warning in derived.warnings(scene))
    fine, _ = load_scene(base_scene())  # dt: auto resolves the contact
    assert not any("steps per" in warning for warning in derived.warnings(fine))
    unstable, _ = load_scene(modified(lambda s: s["time"].update(dt=1e-4)))
    assert any("may be unstable" in warning for warning in derived.warnings(unstable))
    behind, _ = load_scene(modified(lambda s: s["walls"][0].update(point=[0, 0, 0.05])))
    assert any("behind or inside wall 'floor'" in warning for warning in derived.warnings(behind))


@pytest.mark.parametrize("path", sorted(EXAMPLES.glob("*.yaml")), ids=lambda p: p.name)
def test_examples_are_valid_and_warning_free(path):
    scene, base_dir = load_scene(path)
    assert base_dir == EXAMPLES
    # Particles at the start, or a stream that brings them (docs/streams.md).
    assert derived.particle_count(scene) > 0 or any(group.insert.kind == "stream" for group in scene.particles)
    assert derived.warnings(scene) == []


def test_a_missing_mesh_file_is_named_with_its_resolved_path(tmp_path):
    # Any key named `file` or `mesh` holding a string is a path relative to the scene file.
    from pdemfem.scene.schema import WallConfig

    if "file" not in WallConfig.model_fields:
        pytest.skip("mesh walls are not in the scene schema yet")
    folder = tmp_path / "scenes"
    folder.mkdir()
    text = GOOD_YAML + "  - {name: hopper, kind: mesh, file: meshes/hopper.stl, material: glass}\n"
    path = write(folder, "scene.yaml", text)
    error = scene_error(path)
    expected = folder.resolve() / "meshes" / "hopper.stl"
    assert str(error).startswith(f"{path}: line 14: walls[1].file: file not found: {expected}"), str(error)
    assert "relative to the scene file's folder" in str(error)
    expected.parent.mkdir()
    expected.write_text("solid empty\nendsolid empty\n")
    scene, _ = load_scene(path)  # found now
    assert scene.walls[1].file == "meshes/hopper.stl"


def test_drop_onto_a_cylinder():
    from types import SimpleNamespace

    def cylinder(radius, inside):
        axis = SimpleNamespace(point=(0.0, 0.0, 0.0), direction=(2.0, 0.0, 0.0))  # horizontal, along x
        return SimpleNamespace(kind="cylinder", axis=axis, radius=radius, inside=inside, velocity=(0, 0, 0),
                               angular_velocity=(3.0, 0.0, 0.0))

    up = (0.0, 0.0, 1.0)
    drum = cylinder(0.1, inside=True)
    assert derived._drop_to_wall((0.5, 0.0, 0.05), up, drum) == pytest.approx(0.15)  # to the bottom z = -0.1
    assert derived._drop_to_wall((0.5, 0.06, 0.0), up, drum) == pytest.approx(0.08)  # bottom at z = -0.08 there
    assert derived._drop_to_wall((0.5, 0.2, 0.0), up, drum) is None  # outside a drum: not a container
    post = cylinder(0.1, inside=False)
    assert derived._drop_to_wall((0.0, 0.0, 0.3), up, post) == pytest.approx(0.2)  # onto its top
    assert derived._drop_to_wall((0.0, 0.2, 0.3), up, post) is None  # beside it
    vertical = SimpleNamespace(**{**vars(drum), "axis": SimpleNamespace(point=(0, 0, 0), direction=(0, 0, 1))})
    assert derived._drop_to_wall((0.0, 0.0, 0.3), up, vertical) is None
    assert derived._wall_speed(drum) == pytest.approx(0.3)  # |omega| R of the rotating mantle


def test_odd_yaml_shapes_are_explained():
    assert "time: expected a mapping of keys (key: value), got 5" in str(scene_error(modified(lambda s: s.update(time=5))))
    assert "particles[0]: expected a mapping of keys (key: value), got nothing (null)" in str(
        scene_error(modified(lambda s: s.update(particles=[None]))))
    assert "1: key 1 is not a name" in str(scene_error(modified(lambda s: s.update({1: "x"}))))


def test_check_names_the_pair_with_the_fewest_steps_for_its_restitution():
    """The shortest contact (grains on a stiff steel floor, restitution 0.6: 30 steps wanted) is not the one
    that binds: the grains' own contact at restitution 0.4 wants 54.  check printed the shortest contact's
    steps beside the other pair's 54 ('51.0 steps per contact; want >= 54' with no warning)."""
    def change(scene):
        scene["materials"]["steel"] = {"density": 7800, "youngs_modulus": 2e11, "poisson_ratio": 0.3}
        scene["walls"][0]["material"] = "steel"
        scene["interactions"] = {"default": {"restitution": 0.4, "friction": 0.5},
                                 "glass-steel": {"restitution": 0.6, "friction": 0.5}}
    scene = load_scene(modified(change))[0]
    speed = derived.expected_impact_speed(scene)
    durations = derived.contact_duration(scene, speed)
    assert durations.particle_wall < durations.particle_particle  # the wall's contact is the shortest
    dt = durations.particle_particle / 60.0
    pair, steps, need = derived.tightest_contact_resolution(scene, speed, dt)
    assert pair == "particle-particle glass-glass" and steps == pytest.approx(60.0, rel=1e-12)
    assert need == derived.steps_per_contact_required("hertz_mindlin", 0.4) > 50

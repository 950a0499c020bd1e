"""docs/scene_reference.md and docs/scene.md's `check` transcript are generated; they must match the code."""
from __future__ import annotations

import typing

from pdemfem.scene import reference
from pdemfem.scene.schema import Scene


def test_committed_scene_reference_is_current():
    committed = reference.DEFAULT_PATH.read_text()
    assert committed == reference.reference_markdown(), (
        f"docs/scene_reference.md is out of date: run `{reference.UPDATE_COMMAND}` to update it")


def test_scene_guide_transcript_is_current():
    committed = reference.SCENE_GUIDE.read_text()
    assert committed == reference.guide_with_transcript(committed), (
        f"the `pdemfem check` transcript in docs/scene.md is out of date: run `{reference.UPDATE_COMMAND}`")


def _keys(model, path=""):
    """Every key path the schema accepts (as the reference spells them)."""
    for name, field in model.model_fields.items():
        key = f"{path}.{name}" if path else name
        yield key
        for nested in _models(field.annotation):
            text = reference._render(field.annotation, reference._Type())
            suffix = ".<name>" if text.startswith("mapping of name") else "[]" if text.startswith("list of") else ""
            yield from _keys(nested, key + suffix)


def _models(annotation):
    if reference._is_model(annotation):
        yield annotation
    for argument in typing.get_args(annotation):
        yield from _models(argument)


def test_reference_lists_every_key_with_its_unit():
    text = reference.reference_markdown()
    keys = list(_keys(Scene))
    assert len(keys) > 80
    missing = [key for key in keys if f"| `{key}` |" not in text]
    assert missing == []
    # Units come from the descriptions: a few spot checks that the parser finds them.
    for key, unit in (("time.end", "s"), ("materials.<name>.density", "kg/m^3"), ("gravity", "m/s^2"),
                      ("walls[].angular_velocity", "rad/s"), ("solids[].damping.alpha", "1/s")):
        row = next(line for line in text.splitlines() if line.startswith(f"| `{key}` |"))
        assert row.split(" | ")[4] == unit, row


def test_unit_parser_ignores_vectors_and_axis_names():
    assert reference._unit("periodic axes, e.g. [x]") == ""
    assert reference._unit("domain [[xmin,ymin,zmin],[xmax,ymax,zmax]] [m]; more") == "m"
    assert reference._unit("thermal conductivity [W/(m K)]") == "W/(m K)"


def test_check_mode_reports_the_command(tmp_path, capsys):
    stale = tmp_path / "scene_reference.md"
    stale.write_text("old\n")
    assert reference.main(["--check", "--output", str(stale)]) == 1
    assert f"run `{reference.UPDATE_COMMAND}` to update it" in capsys.readouterr().err
    assert stale.read_text() == "old\n"  # --check writes nothing

"""Scene loading: YAML (safe loader only) or a dict -> validated `Scene`.

Every problem a user can make in a scene becomes ONE `SceneError` whose message
names the file, the key path in the user's terms (``particles[0].insert.count``,
``materials.glass.youngs_modulus``), the line in the YAML file when known, the
problem and the fix.  Several problems are listed one per line.

    scene, base_dir = load_scene("scene.yaml")         # base_dir: the scene file's folder
    scene, base_dir = load_scene({"time": ...})        # base_dir: given, else the cwd
    mesh = resolve_path(base_dir, "meshes/beam.msh")   # paths resolve relative to the scene file
    scene_hash(scene)                                  # physics fingerprint for checkpoints

Security: the YAML text goes through ``yaml.safe_load`` (plain data only; no
Python objects can be constructed), and ``yaml.compose`` with the SafeLoader for
line numbers and duplicate keys (composing builds nodes, never objects).
"""
from __future__ import annotations

import difflib
import hashlib
import json
import os
import re
import typing
from pathlib import Path
from typing import Any, Dict, List, Optional, Tuple, Union

import yaml
from pydantic import BaseModel, ValidationError

from pdemfem.errors import SceneError
from pdemfem.scene.schema import Scene

__all__ = [
    "load_scene",
    "resolve_path",
    "input_files",
    "input_file_digests",
    "output_directory",
    "scene_hash",
    "scene_physics",
    "physics_changes",
    "format_key_path",
    "key_line",
    "FILE_KEYS",
    "HASH_EXCLUDED_KEYS",
]

# Keys that do not change the physics of a run: a restart may change them.
HASH_EXCLUDED_KEYS = ("time.end", "output", "checkpoint")

SceneSource = Union[str, os.PathLike, Dict[str, Any], Scene]
KeyPath = Tuple[Union[str, int], ...]


# --------------------------------------------------------------------------- public API


def load_scene(source: SceneSource, base_dir: Optional[Union[str, os.PathLike]] = None) -> Tuple[Scene, Path]:
    """Validate a scene and return ``(scene, base_dir)``.

    ``source`` is a path to a YAML file, a dict (as ``yaml.safe_load`` would give)
    or an already validated `Scene`.  ``base_dir`` is the folder relative paths in
    the scene resolve against: the scene file's folder for a file (the argument is
    then ignored), else ``base_dir`` or the current directory.

    Raises `SceneError` (exit code 2) for every user error, with all validation
    problems in one message.
    """
    if isinstance(source, Scene):
        return source, Path(base_dir or Path.cwd()).resolve()
    if isinstance(source, dict):
        data = source
        label = "<scene dict>"
        nodes = None
        folder = Path(base_dir or Path.cwd()).resolve()
    elif isinstance(source, (str, os.PathLike)):
        path = Path(source).expanduser()
        label = str(source)
        data, nodes = _read_yaml(path, label)
        folder = path.resolve().parent
    else:
        raise SceneError(
            "scene",
            f"cannot load a scene from a {type(source).__name__}",
            "pass the path of a YAML scene file or a dict of its keys",
        )
    if data is None:
        raise SceneError(label, "the scene is empty", "write at least the keys time and materials (see docs/scene.md)")
    if not isinstance(data, dict):
        raise SceneError(
            label,
            f"the scene must be a mapping of keys (time:, materials:, ...), not a {_yaml_type_name(data)}",
            "start the file with top-level keys such as 'time:' and 'materials:' (see docs/scene.md)",
        )
    try:
        scene = Scene.model_validate(data)
    except ValidationError as error:
        problems = _translate(error, data)
        raise _scene_error(label, problems, nodes) from None
    missing = [_file_problem(path, resolve_path(folder, value)) for path, value in _file_keys(scene, ())
               if not resolve_path(folder, value).is_file()]
    # A generated box mesh has exactly the groups xmin..zmax (and the solid's regions): a misspelt group
    # is known before any meshing.
    from pdemfem.scene.inputs import box_mesh_group_problems

    missing += [_Problem(_parse_key_path(key), problem, fix) for key, problem, fix in box_mesh_group_problems(scene)]
    if missing:
        raise _scene_error(label, missing, nodes)
    for group in scene.particles:  # a clump's surface file is read when its shape is first needed
        if group.clump is not None and group.clump.file is not None:
            group.clump._resolved_file = str(resolve_path(folder, group.clump.file))
    return scene, folder


def _file_problem(path: KeyPath, resolved: Path) -> "_Problem":
    """A file key whose path names no regular file: missing, a directory, or something else."""
    if resolved.is_dir():
        return _Problem(path, f"{resolved} is a directory, not a file",
                        f"give the mesh file itself in {format_key_path(path)} (e.g. {resolved}/part.msh); paths "
                        "in a scene are relative to the scene file's folder")
    if resolved.exists():
        return _Problem(path, f"{resolved} is not a regular file", "give the path of a mesh file")
    return _Problem(path, f"file not found: {resolved}",
                    "paths in a scene are relative to the scene file's folder; correct the path or add the file")


# Keys whose string values name files (relative to the scene file): wall meshes, solid meshes.
FILE_KEYS = ("file", "mesh")


def _file_keys(node, path: KeyPath):
    """(key path, value) of every file named in a validated scene."""
    if isinstance(node, BaseModel):
        for name in type(node).model_fields:
            value = getattr(node, name)
            if name in FILE_KEYS and isinstance(value, (str, os.PathLike)):
                yield path + (name,), value
            else:
                yield from _file_keys(value, path + (name,))
    elif isinstance(node, (list, tuple)):
        for index, item in enumerate(node):
            yield from _file_keys(item, path + (index,))
    elif isinstance(node, dict):
        for key, item in node.items():
            yield from _file_keys(item, path + (key,))


def input_files(scene: Scene) -> Dict[str, str]:
    """Every file the scene names (solid meshes, mesh walls, clump shapes) as written, by the key that names it
    ('solids[0].mesh')."""
    return {format_key_path(path): str(value) for path, value in _file_keys(scene, ())}


def input_file_digests(scene: Scene, base_dir: Union[str, os.PathLike]) -> Dict[str, str]:
    """sha256 (hex) of every file of `input_files`, by the same keys: the scene hash covers the keys' text, not
    what the files hold."""
    digests = {}
    for key, value in input_files(scene).items():
        digest = hashlib.sha256()
        with open(resolve_path(base_dir, value), "rb") as handle:
            for block in iter(lambda: handle.read(1 << 20), b""):
                digest.update(block)
        digests[key] = digest.hexdigest()
    return digests


def resolve_path(base_dir: Union[str, os.PathLike], value: Union[str, os.PathLike]) -> Path:
    """A path written in a scene: absolute (after ``~`` expansion) as is, else relative to ``base_dir``."""
    path = Path(value).expanduser()
    if path.is_absolute():
        return path
    return Path(base_dir) / path


def output_directory(
    scene: Scene, base_dir: Union[str, os.PathLike], override: Optional[Union[str, os.PathLike]] = None
) -> Path:
    """Where a run writes: ``override`` (the CLI's ``-o``, relative to the current
    directory) if given, else ``output.dir`` resolved relative to the scene file.  An empty
    override is an error: it would silently mean the current directory."""
    if override is not None and not str(override).strip():
        raise SceneError("output directory (-o / output_dir)", "is empty",
                         "give a directory name, e.g. -o out/run1, or leave it out to use the scene's output.dir")
    if override is not None:
        return Path(override).expanduser().resolve()
    return resolve_path(base_dir, scene.output.dir).resolve()


def scene_physics(scene: Union[Scene, Dict[str, Any]]) -> Dict[str, Any]:
    """The scene's physics as plain data: the validated model with defaults filled in, without
    time.end, output.* and checkpoint.* (what `scene_hash` fingerprints)."""
    if not isinstance(scene, Scene):
        scene, _ = load_scene(scene)
    content = scene.model_dump(mode="json")
    for dotted in HASH_EXCLUDED_KEYS:
        *parents, last = dotted.split(".")
        node = content
        for key in parents:
            node = node.get(key, {}) if isinstance(node, dict) else {}
        if isinstance(node, dict):
            node.pop(last, None)
    return content


def scene_hash(scene: Union[Scene, Dict[str, Any]]) -> str:
    """sha256 (hex) of the scene's physics: everything except time.end, output.* and checkpoint.*.

    Canonical form: the validated model with defaults filled in, dumped to JSON
    with sorted keys, so key order, spelling of numbers (1e-3 vs 0.001) and
    omitted defaults do not change the hash.  Two scenes with the same hash
    continue each other's checkpoints.
    """
    text = json.dumps(scene_physics(scene), sort_keys=True, separators=(",", ":"), allow_nan=True)
    return hashlib.sha256(text.encode("utf-8")).hexdigest()


def physics_changes(old: Any, new: Any, path: KeyPath = (), limit: int = 8) -> List[str]:
    """'key: old -> new' for every value that differs between two `scene_physics` dicts
    (at most `limit`, then '... and N more')."""
    changes: List[str] = []
    _collect_changes(old, new, path, changes)
    if len(changes) > limit:
        changes = changes[:limit] + [f"... and {len(changes) - limit} more"]
    return changes


def _collect_changes(old: Any, new: Any, path: KeyPath, changes: List[str]) -> None:
    if isinstance(old, dict) and isinstance(new, dict):
        for key in list(old) + [key for key in new if key not in old]:
            if key not in new:
                changes.append(f"{format_key_path(path + (key,))}: removed (was {_short(old[key])})")
            elif key not in old:
                changes.append(f"{format_key_path(path + (key,))}: added ({_short(new[key])})")
            else:
                _collect_changes(old[key], new[key], path + (key,), changes)
    elif isinstance(old, list) and isinstance(new, list) and len(old) == len(new):
        for index, (a, b) in enumerate(zip(old, new)):
            _collect_changes(a, b, path + (index,), changes)
    elif old != new:
        changes.append(f"{format_key_path(path)}: {_short(old)} -> {_short(new)}")


def _short(value: Any) -> str:
    text = json.dumps(value, sort_keys=True)
    return text if len(text) <= 60 else text[:57] + "..."


def key_line(scene_file: Union[str, os.PathLike], key: str) -> Optional[int]:
    """1-based line of a key path such as 'particles[0].insert.count' in a YAML scene file
    (the deepest part of the path found), or None when the file cannot be read."""
    try:
        nodes = yaml.compose(Path(scene_file).read_text(encoding="utf-8"), Loader=yaml.SafeLoader)
        return _line_of(nodes, _parse_key_path(key))
    except (OSError, UnicodeDecodeError, yaml.YAMLError, ValueError):
        return None


def format_key_path(path: KeyPath) -> str:
    """('particles', 0, 'insert', 'count') -> 'particles[0].insert.count'."""
    text = ""
    for part in path:
        if isinstance(part, int):
            text += f"[{part}]"
        else:
            text += f".{part}" if text else str(part)
    return text or "(top level)"


# --------------------------------------------------------------------------- YAML


def _read_yaml(path: Path, label: str):
    try:
        text = path.read_text(encoding="utf-8")
    except FileNotFoundError:
        raise SceneError(label, "scene file not found", f"check the path (current directory: {Path.cwd()})") from None
    except IsADirectoryError:
        raise SceneError(label, "is a directory, not a scene file", "pass the path of a .yaml scene file") from None
    except UnicodeDecodeError as error:
        raise SceneError(label, f"not UTF-8 text ({error.reason} at byte {error.start})", "save the scene as UTF-8 YAML") from None
    except OSError as error:
        raise SceneError(label, f"cannot read the scene file ({error.strerror})", "check the path and its permissions") from None
    try:
        nodes = yaml.compose(text, Loader=yaml.SafeLoader)
        data = yaml.safe_load(text)
    except yaml.constructor.ConstructorError as error:
        mark = error.problem_mark
        where = f"{label}, line {mark.line + 1}, column {mark.column + 1}" if mark else label
        raise SceneError(
            where,
            f"YAML tag not allowed: {error.problem}",
            "scene files hold plain data only (numbers, strings, lists, mappings); remove the '!!' tag",
        ) from None
    except yaml.MarkedYAMLError as error:
        mark = error.problem_mark or error.context_mark
        where = f"{label}, line {mark.line + 1}, column {mark.column + 1}" if mark else label
        problem = error.problem or "invalid YAML"
        if error.context:
            context_mark = error.context_mark
            started = f" that starts at line {context_mark.line + 1}" if context_mark and context_mark is not mark else ""
            problem += f" ({error.context}{started})"
        raise SceneError(
            where, f"YAML syntax error: {problem}", "fix the YAML syntax there (indentation, ':' after keys, closed brackets)"
        ) from None
    except yaml.YAMLError as error:
        raise SceneError(label, f"YAML error: {error}", "fix the YAML syntax") from None
    duplicates = list(_duplicate_keys(nodes, ()))
    if duplicates:
        problems = [
            _Problem(path, f"key '{path[-1]}' appears twice (lines {first} and {second}); YAML would silently keep the last",
                     "keep one of them", line=second)
            for path, first, second in duplicates
        ]
        raise _scene_error(label, problems, None)
    return data, nodes


def _duplicate_keys(node, path):
    if isinstance(node, yaml.MappingNode):
        seen = {}
        for key_node, value_node in node.value:
            key = key_node.value if isinstance(key_node, yaml.ScalarNode) else None
            if key is not None:
                if key in seen:
                    yield path + (key,), seen[key], key_node.start_mark.line + 1
                else:
                    seen[key] = key_node.start_mark.line + 1
            yield from _duplicate_keys(value_node, path + ((key,) if key is not None else ()))
    elif isinstance(node, yaml.SequenceNode):
        for index, item in enumerate(node.value):
            yield from _duplicate_keys(item, path + (index,))


def _line_of(nodes, path: KeyPath) -> Optional[int]:
    """1-based line of the deepest node on `path` found in the composed YAML."""
    if nodes is None:
        return None
    node = nodes
    line = node.start_mark.line + 1
    for part in path:
        if isinstance(node, yaml.MappingNode):
            for key_node, value_node in node.value:
                if isinstance(key_node, yaml.ScalarNode) and key_node.value == str(part):
                    line = key_node.start_mark.line + 1
                    node = value_node
                    break
            else:
                return line
        elif isinstance(node, yaml.SequenceNode) and isinstance(part, int) and 0 <= part < len(node.value):
            node = node.value[part]
            line = node.start_mark.line + 1
        else:
            return line
    return line


# --------------------------------------------------------------------------- error translation


class _Problem:
    __slots__ = ("path", "problem", "fix", "line", "kind", "suggestion")

    def __init__(self, path: KeyPath, problem: str, fix: str = "", line: Optional[int] = None,
                 kind: str = "", suggestion: Optional[str] = None):
        self.path = tuple(path)
        self.problem = problem
        self.fix = fix
        self.line = line
        self.kind = kind
        self.suggestion = suggestion

    def as_dict(self):
        return {"key": format_key_path(self.path), "problem": self.problem, "fix": self.fix, "line": self.line}


def _scene_error(label: str, problems: List[_Problem], nodes) -> SceneError:
    for problem in problems:
        if problem.line is None:
            problem.line = _line_of(nodes, problem.path)
    if len(problems) == 1:
        (only,) = problems
        where = f"{label}: {format_key_path(only.path)}"
        if only.line is not None:
            where = f"{label}: line {only.line}: {format_key_path(only.path)}"
        error = SceneError(where, only.problem, only.fix)
    else:
        lines = []
        for problem in problems:
            at = f"line {problem.line}: " if problem.line is not None else ""
            lines.append(f"  - {at}{format_key_path(problem.path)}: {problem.problem}")
            if problem.fix:
                lines.append(f"      fix: {problem.fix}")
        error = SceneError(label, f"{len(problems)} problems in the scene:\n" + "\n".join(lines))
    error.problems = [problem.as_dict() for problem in problems]
    return error


_TYPE_WORDS = {
    "float_type": "a number",
    "float_parsing": "a number",
    "finite_number": "a finite number",
    "int_type": "an integer",
    "int_parsing": "an integer",
    "int_from_float": "a whole number (integer)",
    "string_type": "a string",
    "bool_type": "true or false",
    "bool_parsing": "true or false",
    "list_type": "a list [...]",
    "tuple_type": "a list [...]",
    "dict_type": "a mapping of keys (key: value)",
    "model_type": "a mapping of keys (key: value)",
    "model_attributes_type": "a mapping of keys (key: value)",
}

# Examples for a missing required key (see docs/scene.md).
_EXAMPLES = {
    "time": "time: {end: 0.01}",
    "end": "end: 0.01",
    "materials": "materials: {glass: {density: 2500, youngs_modulus: 5.0e6, poisson_ratio: 0.3}}",
    "density": "density: 2500",
    "youngs_modulus": "youngs_modulus: 5.0e6",
    "poisson_ratio": "poisson_ratio: 0.3",
    "name": "name: <a unique name>",
    "material": "material: <a name defined under materials>",
    "radius": "radius: 0.001 or radius: {min: 0.0009, max: 0.0011}",
    "insert": "insert: {kind: lattice, region: {box: [[0,0,0],[0.05,0.05,0.1]]}, count: 1000}",
    "kind": "kind: <see the choices in docs/scene.md>",
    "box": "box: [[x0, y0, z0], [x1, y1, z1]]",
    "min": "min: <smallest radius>",
    "max": "max: <largest radius>",
}

_BOUND_WORDS = {
    "greater_than": ("gt", ">"),
    "greater_than_equal": ("ge", ">="),
    "less_than": ("lt", "<"),
    "less_than_equal": ("le", "<="),
}

# Union members show up in pydantic's error locations as tags such as
# 'constrained-float', "literal['auto']" or 'function-after[_ordered(), RadiusRange]'.
_KEY_PREFIX = re.compile(r"^([A-Za-z_][\w\-]*(?:\[\d+\])*(?:\.[\w\-]+(?:\[\d+\])*)*): (.*)$", re.S)


def _translate(error: ValidationError, data: Dict[str, Any]) -> List[_Problem]:
    # Errors from the members of one union (e.g. radius: number or {min, max}) are
    # grouped at the union's key so that the user gets one message for that key.
    grouped: Dict[Tuple[KeyPath, bool], List[dict]] = {}
    for item in error.errors(include_url=False):
        path, union_at = _user_path(item, data)
        key = (union_at, True) if union_at is not None else (path, False)
        grouped.setdefault(key, []).append(item)
    problems: List[_Problem] = []
    for (path, is_union), items in grouped.items():
        if is_union:
            problems.extend(_union_problems(path, items, data))
        else:
            problems.extend(_one_problem(path, item, data) for item in items)
    problems = _merge_misspellings(problems)
    for problem in problems:
        if not problem.fix:
            section = str(problem.path[0]) if problem.path else "the top-level keys"
            problem.fix = f"see docs/scene.md, section '{section}'"
    return problems


def _merge_misspellings(problems: List[_Problem]) -> List[_Problem]:
    """'bx' unknown + 'box' missing in the same mapping is one problem: a misspelt key."""
    missing = {problem.path: problem for problem in problems if problem.kind == "missing"}
    merged = []
    dropped = set()
    for problem in problems:
        if problem.kind == "extra_forbidden" and problem.suggestion is not None:
            twin = problem.path[:-1] + (problem.suggestion,)
            if twin in missing:
                dropped.add(twin)
                problem.problem = f"unknown key '{problem.path[-1]}' (and the required key '{problem.suggestion}' is missing)"
                problem.fix = f"rename '{problem.path[-1]}' to '{problem.suggestion}'"
        merged.append(problem)
    return [problem for problem in merged if not (problem.kind == "missing" and problem.path in dropped)]


def _user_path(item: dict, data: Any) -> Tuple[KeyPath, Optional[KeyPath]]:
    """The error's key path in the user's terms, and the path of the union it came from (or None).

    pydantic puts union members' tags ('constrained-float', "literal['auto']",
    'function-after[_ordered(), RadiusRange]') into error locations; walking the
    user's data tells tags from keys.
    """
    location = item["loc"]
    node = data
    path: List[Union[str, int]] = []
    union_at: Optional[KeyPath] = None
    for position, part in enumerate(location):
        last = position == len(location) - 1
        if isinstance(node, dict) and part in node:
            path.append(part)
            node = node[part]
        elif isinstance(node, (list, tuple)) and isinstance(part, int):
            path.append(part)
            node = node[part] if 0 <= part < len(node) else None
        elif last and item["type"] in ("missing", "extra_forbidden") and isinstance(node, (dict, list, tuple)):
            path.append(part)
        elif union_at is None:
            union_at = tuple(path)
    return tuple(path), union_at


def _union_problems(path: KeyPath, items: List[dict], data: Any) -> List[_Problem]:
    """One message for a value that matched none of the types a key accepts."""
    type_errors = [item for item in items if item["type"] in _TYPE_WORDS or item["type"] == "literal_error"]
    value_errors = [item for item in items if item not in type_errors]
    if value_errors:
        # The user's value had the right shape for one member: report that member's complaint.
        return [_one_problem(_user_path(item, data)[0], item, data) for item in value_errors]
    accepted = []
    for item in type_errors:
        words = _expected_words(item)
        if words not in accepted:
            accepted.append(words)
    value = items[0].get("input")
    return [
        _Problem(
            path,
            f"expected {' or '.join(accepted)}, got {_show(value)}",
            f"write {format_key_path(path)} as {' or '.join(accepted)}",
        )
    ]


def _expected_words(item: dict) -> str:
    if item["type"] == "literal_error":
        expected = str(item.get("ctx", {}).get("expected", ""))
        return expected if " or " not in expected else "one of " + expected
    return _TYPE_WORDS[item["type"]]


def _one_problem(path: KeyPath, item: dict, data: Any) -> _Problem:
    kind = item["type"]
    value = item.get("input")
    key = format_key_path(path)
    if kind == "extra_forbidden":
        parent = path[:-1]
        unknown = str(path[-1])
        valid = _valid_keys(parent)
        if valid:
            close = difflib.get_close_matches(unknown, valid, n=1, cutoff=0.6)
            listing = "valid keys here: " + ", ".join(valid)
            fix = f"did you mean '{close[0]}'? ({listing})" if close else f"remove it or rename it ({listing})"
        else:
            close = []
            fix = "remove it"
        return _Problem(path, f"unknown key '{unknown}'", fix, kind=kind, suggestion=close[0] if close else None)
    if kind == "missing":
        parent_value = _value_at(data, path[:-1])
        if isinstance(path[-1], int) and isinstance(parent_value, (list, tuple)):
            return _Problem(
                path[:-1],
                f"too few values: got {len(parent_value)} ({_show(parent_value)})",
                "give all three components [x, y, z]" if path[-1] <= 2 else "give the full list of values",
            )
        description = _field_description(path)
        example = _EXAMPLES.get(str(path[-1]))
        fix = f"add {path[-1]}: <value>" + (f" ({description})" if description else "")
        if example:
            fix += f", e.g. {example}"
        return _Problem(path, f"required key '{path[-1]}' is missing", fix, kind=kind)
    if kind == "invalid_key":
        name = str(path[-1]) if path else str(value)
        return _Problem(path[:-1] + (name,), f"key {name} is not a name",
                        "keys are names such as time or materials; rename it (or quote it: '1')")
    if kind == "string_too_short":
        return _Problem(path, "is empty", f"give {key} a value (a name or a path relative to the scene file)")
    if kind in ("too_long", "too_short"):
        expected = item.get("ctx", {}).get("max_length" if kind == "too_long" else "min_length")
        count = item.get("ctx", {}).get("actual_length")
        expected_text = f"{expected} values" if expected is not None else "a different number of values"
        got = f", got {count}" if count is not None else ""
        fix = "give all three components [x, y, z]" if expected == 3 else f"give {expected_text}"
        return _Problem(path, f"expected {expected_text}{got}", fix)
    if kind in _BOUND_WORDS:
        name, symbol = _BOUND_WORDS[kind]
        bound = item.get("ctx", {}).get(name)
        return _Problem(
            path, f"must be {symbol} {bound:g}, got {_show(value)}" if isinstance(bound, (int, float)) else f"{item['msg']}, got {_show(value)}",
            _bound_fix(path, symbol, bound),
        )
    if kind == "literal_error":
        expected = item.get("ctx", {}).get("expected", "")
        close = difflib.get_close_matches(str(value), re.findall(r"'([^']*)'", expected), n=1, cutoff=0.5)
        fix = f"did you mean '{close[0]}'? (choices: {expected})" if close else f"use one of {expected}"
        return _Problem(path, f"{_show(value)} is not a valid choice", fix)
    if kind in _TYPE_WORDS:
        words = _TYPE_WORDS[kind]
        return _Problem(path, f"expected {words}, got {_show(value)}", f"write {key} as {words}")
    if kind in ("value_error", "assertion_error"):
        message = str(item.get("ctx", {}).get("error", item["msg"]))
        if not path:
            match = _KEY_PREFIX.match(message)
            if match:
                path = _parse_key_path(match.group(1))
                message = match.group(2)
        problem, _, fix = message.partition("; ")
        return _Problem(path, problem, fix)
    return _Problem(path, f"{item['msg']} (got {_show(value)})", "see docs/scene.md for this key")


def _bound_fix(path: KeyPath, symbol: str, bound) -> str:
    if path and isinstance(path[-1], int):
        # An entry of a list (mesh.cells[0], a radius in radii): name the list and the entry, not the bare index.
        listing = format_key_path(path[:-1])
        key = format_key_path(path)
        if symbol == ">" and bound == 0:
            return f"every entry of {listing} must be positive: give {key} a value > 0"
        if symbol == ">=" and bound == 0:
            return f"every entry of {listing} must be zero or more: give {key} a value >= 0"
        return f"give {key} a value {symbol} {bound:g}" if isinstance(bound, (int, float)) else f"correct {key}"
    name = str(path[-1]) if path else "value"
    if symbol == ">" and bound == 0:
        return f"{name} must be positive (SI units)"
    if symbol == ">=" and bound == 0:
        return f"{name} must not be negative"
    return f"use a value {symbol} {bound}"


def _parse_key_path(text: str) -> KeyPath:
    path: List[Union[str, int]] = []
    for part in text.split("."):
        name, *indices = re.split(r"\[", part)
        path.append(name)
        path.extend(int(index.rstrip("]")) for index in indices)
    return tuple(path)


def _value_at(data: Any, path: KeyPath) -> Any:
    node = data
    for part in path:
        try:
            node = node[part]
        except (KeyError, IndexError, TypeError):
            return None
    return node


def _show(value: Any) -> str:
    if isinstance(value, (dict, list, tuple)):
        text = json.dumps(value, default=str)
        return text if len(text) <= 60 else text[:57] + "..."
    if isinstance(value, str):
        return f"'{value}' (text)"
    if value is None:
        return "nothing (null)"
    return repr(value)


def _yaml_type_name(value: Any) -> str:
    if isinstance(value, list):
        return "list"
    if isinstance(value, str):
        return "string"
    return type(value).__name__


# --------------------------------------------------------------------------- schema walking


def _unwrap(annotation):
    """Strip Annotated / Optional; return the annotation itself otherwise."""
    while True:
        origin = typing.get_origin(annotation)
        if origin is typing.Annotated:
            annotation = typing.get_args(annotation)[0]
            continue
        if origin is Union:
            members = [arg for arg in typing.get_args(annotation) if arg is not type(None)]
            models = [
                member
                for member in members
                if _is_model(_strip_annotated(member))
                or typing.get_origin(_strip_annotated(member)) in (list, dict, tuple)
            ]
            if len(members) == 1:
                annotation = members[0]
                continue
            if models:
                annotation = models[0]
                continue
        return annotation


def _strip_annotated(annotation):
    while typing.get_origin(annotation) is typing.Annotated:
        annotation = typing.get_args(annotation)[0]
    return annotation


def _is_model(annotation) -> bool:
    return isinstance(annotation, type) and issubclass(annotation, BaseModel)


def _schema_at(path: KeyPath):
    """The schema type (model class, list/dict annotation) a key path points into."""
    current: Any = Scene
    for part in path:
        current = _unwrap(current)
        if _is_model(current):
            field = current.model_fields.get(part) if isinstance(part, str) else None
            if field is None:
                return None
            current = field.annotation
            continue
        origin = typing.get_origin(current)
        args = typing.get_args(current)
        if origin in (list, List) and args:
            current = args[0]
        elif origin in (dict, Dict) and len(args) == 2:
            current = args[1]
        elif origin in (tuple, Tuple) and args:
            current = args[part] if isinstance(part, int) and part < len(args) and args[-1] is not Ellipsis else args[0]
        else:
            return None
    return _unwrap(current)


def _valid_keys(path: KeyPath) -> List[str]:
    model = _schema_at(path)
    if _is_model(model):
        return list(model.model_fields)
    return []


def _field_description(path: KeyPath) -> str:
    model = _schema_at(path[:-1])
    if _is_model(model) and isinstance(path[-1], str):
        field = model.model_fields.get(path[-1])
        if field is not None and field.description:
            return field.description
    return ""

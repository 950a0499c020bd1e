"""The walls package: every module imports on its own, no import cycle, no import of the scene layer."""
from __future__ import annotations

import ast
import subprocess
import sys
from pathlib import Path

import pdemfem
from pdemfem.runtime import process_environment

WALLS = Path(pdemfem.__file__).parent / "walls"
MODULES = sorted(path.stem for path in WALLS.glob("*.py") if path.stem != "__init__")


def imported_modules(path: Path) -> set:
    """Every module a file imports, at module level or inside functions (absolute names)."""
    names = set()
    for node in ast.walk(ast.parse(path.read_text())):
        if isinstance(node, ast.Import):
            names.update(alias.name for alias in node.names)
        elif isinstance(node, ast.ImportFrom) and node.module:
            names.add(node.module)
            names.update(f"{node.module}.{alias.name}" for alias in node.names)
    return names


def test_each_walls_module_imports_alone_in_a_fresh_interpreter():
    processes = {name: subprocess.Popen([sys.executable, "-c", f"import pdemfem.walls.{name}"],
                                        env=process_environment(), stdout=subprocess.PIPE, stderr=subprocess.PIPE,
                                        text=True)
                 for name in MODULES}
    failures = {}
    for name, process in processes.items():
        _, error = process.communicate(timeout=120)
        if process.returncode:
            failures[name] = error.strip().splitlines()[-1:]
    assert not failures, failures


def test_walls_imports_form_no_cycle():
    """Also the imports inside functions: a deferred import only hides a cycle until it runs."""
    graph = {name: {other for other in MODULES if f"pdemfem.walls.{other}" in imported_modules(WALLS / f"{name}.py")}
             for name in MODULES}
    visiting, done = set(), set()

    def visit(name, trail):
        if name in visiting:
            raise AssertionError("import cycle: " + " -> ".join(trail + [name]))
        if name in done:
            return
        visiting.add(name)
        for other in sorted(graph[name]):
            visit(other, trail + [name])
        visiting.discard(name)
        done.add(name)

    for name in MODULES:
        visit(name, [])


def test_walls_do_not_import_the_scene_layer():
    offenders = {name: sorted(module for module in imported_modules(WALLS / f"{name}.py")
                              if module == "pdemfem.scene" or module.startswith("pdemfem.scene."))
                 for name in MODULES}
    assert not {name: found for name, found in offenders.items() if found}

"""Run a command (optionally under mpiexec) with pdemfem's process environment.

    python -m pdemfem.launch -n 2 -- pdemfem run scene.yaml
    python -m pdemfem.launch --print-env
"""
from __future__ import annotations

import os
import shutil
import sys

from pdemfem.runtime import mpiexec_command, process_environment


def main(argv: list[str] | None = None) -> int:
    arguments = list(sys.argv[1:] if argv is None else argv)
    if arguments[:1] == ["--print-env"]:
        for key, value in sorted(process_environment({}).items()):
            print(f"export {key}={value}")
        return 0
    ranks = 1
    if arguments[:1] == ["-n"]:
        ranks = int(arguments[1])
        arguments = arguments[2:]
    if arguments[:1] == ["--"]:
        arguments = arguments[1:]
    if not arguments:
        print("usage: python -m pdemfem.launch [-n RANKS] -- COMMAND ...", file=sys.stderr)
        return 2
    executable = _resolve(arguments[0])
    if executable is None:
        # mpiexec would fail on every rank with its own report silenced (orte_execute_quiet): say it here.
        print(f"error: command '{arguments[0]}' not found on PATH nor beside {sys.executable}\n"
              f"  fix: activate the environment (source .venv/bin/activate) or give the command's full path",
              file=sys.stderr)
        return 2
    arguments = [executable, *arguments[1:]]
    command = mpiexec_command(ranks, arguments) if ranks > 1 else arguments
    environment = process_environment()
    os.execvpe(command[0], command, environment)
    return 0  # not reached


def _resolve(name: str) -> str | None:
    """The command's path: as given when it is a path, else from PATH, else beside this Python (the
    environment's bin folder, for `pdemfem` run through the environment's python without activating it)."""
    if os.sep in name:
        return name if os.access(name, os.X_OK) else None
    found = shutil.which(name)
    if found:
        return found
    beside = os.path.join(os.path.dirname(sys.executable), name)
    return beside if os.access(beside, os.X_OK) else None


if __name__ == "__main__":
    sys.exit(main())

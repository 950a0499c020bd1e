"""Run a command (optionally under mpiexec) with pdemfem's process environment.

    python -m pdemfem.launch -n 2 -- pdemfem run scene.yaml
    python -m pdemfem.launch --print-env
"""
from __future__ import annotations

import argparse
import os
import shutil
import sys

from pdemfem.runtime import mpiexec_command, process_environment


def _parser() -> argparse.ArgumentParser:
    parser = argparse.ArgumentParser(
        prog="python -m pdemfem.launch",
        description="Run a command with pdemfem's process environment (PETSc, Open MPI as root and "
                    "oversubscription, one thread per rank), under mpiexec when RANKS > 1.",
        epilog="example: python -m pdemfem.launch -n 2 -- pdemfem run scene.yaml")
    parser.add_argument("-n", "--ranks", type=int, default=1, metavar="RANKS", help="MPI ranks (default 1)")
    parser.add_argument("--print-env", action="store_true",
                        help="print the environment as export lines (for a job script) and exit")
    parser.add_argument("command", nargs=argparse.REMAINDER, help="the command and its arguments, after --")
    return parser


def main(argv: list[str] | None = None) -> int:
    parser = _parser()
    options = parser.parse_args(list(sys.argv[1:] if argv is None else argv))
    if options.print_env:
        for key, value in sorted(process_environment({}).items()):
            print(f"export {key}={value}")
        return 0
    ranks = options.ranks
    arguments = options.command[1:] if options.command[:1] == ["--"] else options.command
    if ranks < 1:
        parser.error(f"-n {ranks}: give at least 1 rank")
    if not arguments:
        parser.error("no command: give it after --, e.g. -- pdemfem run scene.yaml")
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

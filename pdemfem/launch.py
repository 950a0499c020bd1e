"""Run a command (optionally under mpiexec) with pdemfem's process environment.

    python -m pdemfem.launch -n 2 -- pdemfem run scene.yaml
    python -m pdemfem.launch --print-env
"""
from __future__ import annotations

import os
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
    command = mpiexec_command(ranks, arguments) if ranks > 1 else arguments
    environment = process_environment()
    os.execvpe(command[0], command, environment)
    return 0  # not reached


if __name__ == "__main__":
    sys.exit(main())

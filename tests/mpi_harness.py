"""Run a Python script under mpiexec with pdemfem's process environment.

Parallel tests put the case in a script (tests/mpi_cases/*.py) that writes its
results to a file; the test runs it on 1, 2 and 3 ranks and compares.
"""
from __future__ import annotations

import subprocess
import sys
from pathlib import Path

from pdemfem.runtime import mpiexec_command, process_environment

CASES = Path(__file__).parent / "mpi_cases"


def run_under_mpi(ranks: int, script: str | Path, *arguments: str, timeout: float = 300.0, cwd=None):
    """Run `script` on `ranks` processes; fail the test with its output if it fails."""
    script = Path(script)
    if not script.is_absolute():
        script = CASES / script
    command = mpiexec_command(ranks, [sys.executable, str(script), *map(str, arguments)])
    completed = subprocess.run(
        command, env=process_environment(), capture_output=True, text=True, timeout=timeout, cwd=cwd
    )
    if completed.returncode != 0:
        raise AssertionError(
            f"{' '.join(command)} exited {completed.returncode}\n--- stdout\n{completed.stdout}\n--- stderr\n{completed.stderr}"
        )
    return completed

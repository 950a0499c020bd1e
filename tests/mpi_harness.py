"""Run a Python script under mpiexec with pdemfem's process environment.

Parallel tests put the case in a script (tests/mpi_cases/*.py) that writes its
results to a file; the test runs it on 1, 2 and 3 ranks and compares.  Also:
what ParaView's pvpython sees in XDMF series (paraview_views).
"""
from __future__ import annotations

import json
import os
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


def paraview_views(pvpython: str, *xdmf_files) -> list:
    """What ParaView's Xdmf3 reader sees in each file (mpi_cases/io_paraview.py, one dict per file: times, points,
    cells, arrays, sums), run by `pvpython` outside the venv (its own Python) and without a display."""
    environment = {k: v for k, v in os.environ.items() if k not in ("PYTHONPATH", "PYTHONHOME", "VIRTUAL_ENV")}
    environment.setdefault("QT_QPA_PLATFORM", "offscreen")
    completed = subprocess.run([pvpython, str(CASES / "io_paraview.py"), *(str(Path(f).resolve()) for f in xdmf_files)],
                               capture_output=True, text=True, timeout=180, env=environment)
    assert completed.returncode == 0, completed.stderr[-3000:]
    return [json.loads(line) for line in completed.stdout.splitlines() if line.startswith("{")]

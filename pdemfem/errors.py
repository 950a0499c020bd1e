"""User-facing errors: one clear message naming the key or file and the fix.

Every error a user can cause with a scene, mesh or checkpoint is raised as a
subclass of PdemfemError; the CLI prints its message on rank 0 and every rank
exits with `exit_code` together (see pdemfem.cli).
"""
from __future__ import annotations


class PdemfemError(Exception):
    """An error caused by the user's input, reported without a traceback."""

    exit_code = 2

    def __init__(self, where: str, problem: str, fix: str = ""):
        self.where = where
        self.problem = problem
        self.fix = fix
        message = f"{where}: {problem}"
        if fix:
            message += f"\n  fix: {fix}"
        super().__init__(message)


class SceneError(PdemfemError):
    """A scene file or dict that is invalid (`where` is the file and key path)."""


class MeshError(PdemfemError):
    """A mesh file that cannot be used (`where` is the file and group)."""


class CheckpointError(PdemfemError):
    """A checkpoint that cannot be restarted from."""


class OutputError(PdemfemError):
    """An output or checkpoint location that cannot be used (exists with results, not writable, full)."""


class SolverError(PdemfemError):
    """A numerical failure the user can act on (diverged solve, unstable step)."""

    exit_code = 3

"""Before a run writes: never overwrite or mix an earlier run's results silently.

    prepare_output(output_dir, checkpoint_dir, comm, restart=False, force=False, clear=True)

Collective; rank 0 looks at the disk and every rank raises the same PdemfemError.

* The output directory holds an earlier run's results (history.csv, an XDMF/HDF5 series or
  an .h5 data file alone, plots): refused unless the run continues from a checkpoint (`restart`) or `force` (start
  afresh: with `clear`, those files are deleted first, so old and new never mix).
* The checkpoint directory holds checkpoints (checkpoint_*.h5, latest.h5) and the run does not
  continue from one: refused even with `force` -- a run never deletes or overwrites checkpoints
  it did not write (the user deletes or moves them, or continues them with --restart).  The state a
  diverged run stopped at (checkpoint_<step>_diverged.h5) counts with the results: `force` deletes it.
* Both directories must be writable: each is created and a probe file written and removed, so
  a read-only or impossible location is one clear error before the first step, not a traceback
  from the first write.  A checkpoint directory created only for the probe is removed again.
"""
from __future__ import annotations

import secrets
from pathlib import Path

from pdemfem.errors import OutputError

HISTORY = "history.csv"
PLOTS = "plots"
CHECKPOINT_PATTERNS = ("checkpoint_*.h5", "latest.h5")
# The state a diverged run stopped at, checkpoint_<step>_diverged.h5: kept for inspection, never latest.h5, never
# pruned, and counted with the run's results (what --force replaces), not with the checkpoints to continue.
DIVERGED_SUFFIX = "_diverged"


def previous_results(output_dir: Path) -> list:
    """The files of an earlier run in `output_dir` (history, field series, plots of them)."""
    output_dir = Path(output_dir)
    if not output_dir.is_dir():
        return []
    found = []
    if (output_dir / HISTORY).is_file():
        found.append(output_dir / HISTORY)
    for index in sorted(output_dir.glob("*.xdmf")):
        found.append(index)
    # The series' data, also without its index (a user who moved or deleted the .xdmf still has the results);
    # checkpoints are the other rule's (they may share the folder through checkpoint.dir).
    checkpoints = set(previous_checkpoints(output_dir))
    found.extend(path for path in sorted(output_dir.glob("*.h5")) if path not in checkpoints)
    if (output_dir / PLOTS).is_dir():
        found.extend(sorted((output_dir / PLOTS).glob("*.png")))
    return found


def previous_checkpoints(checkpoint_dir: Path) -> list:
    checkpoint_dir = Path(checkpoint_dir)
    if not checkpoint_dir.is_dir():
        return []
    return sorted({path for pattern in CHECKPOINT_PATTERNS for path in checkpoint_dir.glob(pattern)})


def _names(paths, folder: Path, shown: int = 4) -> str:
    names = [str(Path(path).relative_to(folder)) if Path(path).is_relative_to(folder) else str(path)
             for path in paths]
    return ", ".join(names[:shown]) + (f" and {len(names) - shown} more" if len(names) > shown else "")


def _not_a_directory(directory: Path, key: str, option: str):
    """(where, problem, fix) when `directory` or one of its parents exists but is not a directory."""
    for path in [directory, *directory.parents]:
        if path.exists() and not path.is_dir():
            what = "it is" if path == directory else f"its parent {path} is"
            return (str(directory), f"cannot be the {key}: {what} an existing file, not a directory",
                    f"give {option} the path of a directory (existing or new), or move the file {path} away")
        if path.exists():
            return None
    return None


def _check_on_root(output_dir: Path, checkpoint_dir: Path, restart: bool, force: bool, clear: bool):
    """None, or (where, problem, fix) of the refusal."""
    for directory, key, option in ((output_dir, "output directory", "-o (or output.dir)"),
                                   (checkpoint_dir, "checkpoint directory", "checkpoint.dir")):
        refusal = _not_a_directory(Path(directory), key, option)
        if refusal is not None:
            return refusal
    if not restart:
        every = previous_checkpoints(checkpoint_dir)
        stopped = [path for path in every if path.stem.endswith(DIVERGED_SUFFIX)]
        checkpoints = [path for path in every if path not in stopped]
        if checkpoints:
            return (str(checkpoint_dir),
                    f"holds checkpoints of an earlier run ({_names(checkpoints, checkpoint_dir)}); a run never "
                    f"deletes or overwrites checkpoints it did not write, not even with --force",
                    f"continue that run with --restart {checkpoint_dir}, or move or delete them "
                    f"(rm -r {checkpoint_dir}), or write elsewhere (-o DIR / checkpoint.dir)")
        results = previous_results(output_dir) + stopped
        if results and not force:
            return (str(output_dir),
                    f"holds the results of an earlier run ({_names(results, output_dir)}); a new run would "
                    f"overwrite them",
                    "add --force (Python: force=True) to start afresh (deletes those files), continue that run "
                    "with --restart CHECKPOINT, or write elsewhere (-o DIR / output_dir=)")
        if results and clear:
            for path in results:
                try:
                    path.unlink()
                except OSError as error:
                    return (str(path), f"cannot delete the earlier run's file ({error.strerror})",
                            "check the permissions of the output directory, or write elsewhere (-o DIR)")
    for directory, key, keep in ((output_dir, "output directory (output.dir / -o)", True),
                                 (checkpoint_dir, "checkpoint directory (checkpoint.dir)", False)):
        problem = _probe_writable(Path(directory), keep_created=keep)
        if problem is not None:
            return (str(directory), f"the {key} is not writable ({problem})",
                    "choose a directory you can write to (and with free space), or fix its permissions")
    return None


def _probe_writable(directory: Path, keep_created: bool):
    """None if a file can be created in `directory` (created if missing), else the OS's reason."""
    missing = []
    parent = directory
    while not parent.exists() and parent != parent.parent:
        missing.append(parent)
        parent = parent.parent
    try:
        directory.mkdir(parents=True, exist_ok=True)
        probe = directory / f".pdemfem-write-probe-{secrets.token_hex(4)}"
        with open(probe, "w") as handle:
            handle.write("probe")
        probe.unlink()
    except OSError as error:
        return f"{error.strerror or error}: {error.filename or directory}"
    finally:
        if not keep_created:
            for created in missing:  # deepest first
                try:
                    created.rmdir()
                except OSError:
                    break
    return None


def prepare_output(output_dir, checkpoint_dir, comm, restart: bool = False, force: bool = False,
                   clear: bool = True) -> None:
    """Collective: refuse to overwrite or mix an earlier run's files (module docstring); with
    `force` and `clear`, delete the earlier results; make sure both directories are writable."""
    refusal = None
    if comm.rank == 0:
        refusal = _check_on_root(Path(output_dir), Path(checkpoint_dir), restart, force, clear)
    if comm.size > 1:
        refusal = comm.bcast(refusal, root=0)
    if refusal is not None:
        raise OutputError(*refusal)


def agree_on_error(comm, message):
    """Collective: the first rank's error message, or None when no rank failed (one allgather)."""
    if comm.size == 1:
        return message
    return next((text for text in comm.allgather(message) if text is not None), None)


def write_error_text(error: BaseException) -> str:
    """A one-line description of a failed write (errno text first: 'No space left on device')."""
    if isinstance(error, OSError) and error.strerror:
        return f"{error.strerror}" + (f": {error.filename}" if error.filename else "")
    return f"{type(error).__name__}: {error}"


__all__ = ["prepare_output", "previous_results", "previous_checkpoints", "agree_on_error", "write_error_text"]

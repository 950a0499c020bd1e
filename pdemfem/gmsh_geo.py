"""Mesh a gmsh .geo file: quietly, deterministically, errors as MeshError.

    with gmsh_session():
        mesh_geo_file(path, dimension=3)   # the mesh is now gmsh's current model: read it with gmsh.model.mesh
        ...

Used by the solid reader (3-D: tetrahedra and the physical surface groups) and the surface-wall
reader (2-D: the surface triangles).  The same .geo file gives the same mesh, bit for bit: a fresh
gmsh session starts from gmsh's defaults (no user option files are read), meshes on one thread with
a fixed random seed.

gmsh's .geo parser keeps state across sessions (gmsh.finalize does not reset it): after a file it
stopped reading in the middle of a statement (a syntax error, an unknown variable, or a corrupt .msh,
which gmsh falls back to parsing as a script), the next files it parses are misread or silently
read as empty.  So the file is meshed in this process until gmsh has once failed to read a file
here; after that, in a fresh Python process that saves the mesh as a .msh, which this process then
reads (the same mesh: tests/test_geo_meshes.py).  In a run a read failure stops the run, so only a
program that goes on after a MeshError (a test suite, an interactive session) pays the ~0.3 s of the
child process per file.
"""
from __future__ import annotations

import contextlib
import json
import subprocess
import sys
import tempfile
from pathlib import Path

from pdemfem.errors import MeshError

# gmsh's own default, stated so a changed default cannot change the mesh silently.
RANDOM_SEED = 1
# Options a .geo file may set that would make the mesh depend on the machine: forced after reading it.
SINGLE_THREAD_OPTIONS = ("General.NumThreads", "Mesh.MaxNumThreads1D", "Mesh.MaxNumThreads2D", "Mesh.MaxNumThreads3D")

# Set once gmsh failed to read a file in this process: its .geo parser can no longer be trusted here.
_parser_state = {"failed": False}

# The child process: mesh the .geo file in a fresh gmsh, save a binary (exact) .msh; on failure print
# {"stage": "read" or "mesh", "message": gmsh's message} and exit 1.  Only gmsh is imported (not
# pdemfem, whose import sets up MPI and PETSc).
_CHILD = r"""
import json, sys
import gmsh
geo, msh, dimension, seed = sys.argv[1], sys.argv[2], int(sys.argv[3]), int(sys.argv[4])
single_thread = sys.argv[5].split(",")
gmsh.initialize(readConfigFiles=False, interruptible=False)
gmsh.option.setNumber("General.Terminal", 0)
gmsh.option.setNumber("Mesh.RandomSeed", seed)
stage = "read"
try:
    gmsh.open(geo)
    for name in single_thread:
        gmsh.option.setNumber(name, 1)
    stage = "mesh"
    gmsh.model.mesh.generate(dimension)
    # A .msh holds only the elements of physical groups when there are any: group every entity of the
    # dimension read if none of it is grouped, as the in-process reading takes them all then.
    if not gmsh.model.getPhysicalGroups(dimension) and gmsh.model.getPhysicalGroups():
        gmsh.model.addPhysicalGroup(dimension, [tag for _, tag in gmsh.model.getEntities(dimension)])
    gmsh.option.setNumber("Mesh.Binary", 1)
    gmsh.write(msh)
except Exception as error:
    print(json.dumps({"stage": stage, "message": str(error)}))
    sys.exit(1)
finally:
    gmsh.finalize()
"""


@contextlib.contextmanager
def gmsh_session():
    """A gmsh session that prints nothing: opened (and closed) here unless the caller already runs one."""
    import gmsh

    initialized_here = not gmsh.isInitialized()
    if initialized_here:
        # No ~/.gmshrc or option files: the mesh must not depend on who runs it.
        gmsh.initialize(readConfigFiles=False, interruptible=False)
    try:
        gmsh.option.setNumber("General.Terminal", 0)
        yield
    finally:
        if initialized_here:
            gmsh.finalize()


def note_read_failure() -> None:
    """gmsh failed to read a file in this process (its parser may keep the broken file's state)."""
    _parser_state["failed"] = True


def mesh_geo_file(path, dimension: int) -> None:
    """Read the .geo file at `path` and mesh it up to `dimension` (2: surfaces, 3: volumes) into the
    current gmsh session's model; a MeshError naming the file and gmsh's message if gmsh cannot."""
    import gmsh

    source = str(path)
    if not _parser_state["failed"]:
        gmsh.option.setNumber("Mesh.RandomSeed", RANDOM_SEED)
        try:
            gmsh.open(source)
        except Exception as error:  # gmsh raises a bare Exception carrying its last error message
            note_read_failure()
            raise _read_error(source, str(error)) from None
        # An empty model from a .geo: either the file defines nothing, or a parser left broken by a
        # failure outside pdemfem's readers read it as empty; the child process tells them apart.
        if gmsh.model.getEntities():
            _generate(source, dimension)
            return
    _mesh_in_child_process(source, dimension)


def _generate(source: str, dimension: int) -> None:
    import gmsh

    # After the file: a .geo may set options, but the mesh must not depend on the thread count.
    for name in SINGLE_THREAD_OPTIONS:
        gmsh.option.setNumber(name, 1)
    try:
        gmsh.model.mesh.generate(dimension)
    except Exception as error:
        raise _mesh_error(source, dimension, str(error)) from None


def _mesh_in_child_process(source: str, dimension: int) -> None:
    """Mesh the file in a fresh Python process and open the .msh it saves in the current session."""
    import gmsh

    with tempfile.TemporaryDirectory(prefix="pdemfem_geo_") as folder:
        msh = str(Path(folder) / "mesh.msh")
        done = subprocess.run([sys.executable, "-c", _CHILD, source, msh, str(dimension), str(RANDOM_SEED),
                               ",".join(SINGLE_THREAD_OPTIONS)], capture_output=True, text=True)
        if done.returncode != 0:
            try:
                report = json.loads(done.stdout.strip().splitlines()[-1])
            except (ValueError, IndexError):
                report = {"stage": "read", "message": (done.stderr.strip().splitlines() or ["gmsh failed"])[-1]}
            if report["stage"] == "mesh":
                raise _mesh_error(source, dimension, report["message"])
            raise _read_error(source, report["message"])
        gmsh.open(msh)


def _read_error(source: str, message: str) -> MeshError:
    return MeshError(where=source, problem=f"gmsh cannot read the .geo file ({_one_line(message)})",
                     fix="correct the .geo file at the place gmsh names (open it in the gmsh GUI to see it)")


def _mesh_error(source: str, dimension: int, message: str) -> MeshError:
    what = "volume" if dimension == 3 else "surface"
    return MeshError(where=source, problem=f"gmsh cannot mesh the {what} ({_one_line(message)})",
                     fix="correct the geometry or the mesh sizes in the .geo file (try it in the gmsh GUI: "
                         f"Mesh > {dimension}D)")


def _one_line(message: str) -> str:
    return " ".join(message.split()) or "no message"

"""Mesh a gmsh .geo file in memory: quietly, deterministically, errors as MeshError.

    with gmsh_session():
        mesh_geo_file(path, dimension=3)   # the mesh is now gmsh's current model: read it with gmsh.model.mesh
        ...

Used by the solid reader (3-D: tetrahedra and the physical surface groups) and the surface-wall
reader (2-D: the surface triangles).  The same .geo file gives the same mesh, bit for bit: a fresh
gmsh session starts from gmsh's defaults (no user option files are read), meshes on one thread with
a fixed random seed.
"""
from __future__ import annotations

import contextlib

from pdemfem.errors import MeshError

# gmsh's own default, stated so a changed default cannot change the mesh silently.
RANDOM_SEED = 1


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


def mesh_geo_file(path, dimension: int) -> None:
    """Read the .geo file at `path` and mesh it up to `dimension` (2: surfaces, 3: volumes) in the
    current gmsh session; a MeshError naming the file and gmsh's message if gmsh cannot."""
    import gmsh

    source = str(path)
    gmsh.option.setNumber("Mesh.RandomSeed", RANDOM_SEED)
    try:
        gmsh.open(source)
    except Exception as error:  # gmsh raises a bare Exception carrying its last error message
        raise MeshError(where=source, problem=f"gmsh cannot read the .geo file ({_message(error)})",
                        fix="correct the .geo file at the place gmsh names (open it in the gmsh GUI to see it)") from None
    # After the file: a .geo may set options, but the mesh must not depend on the thread count.
    gmsh.option.setNumber("General.NumThreads", 1)
    gmsh.option.setNumber("Mesh.MaxNumThreads1D", 1)
    gmsh.option.setNumber("Mesh.MaxNumThreads2D", 1)
    gmsh.option.setNumber("Mesh.MaxNumThreads3D", 1)
    try:
        gmsh.model.mesh.generate(dimension)
    except Exception as error:
        what = "volume" if dimension == 3 else "surface"
        raise MeshError(where=source, problem=f"gmsh cannot mesh the {what} ({_message(error)})",
                        fix="correct the geometry or the mesh sizes in the .geo file (try it in the gmsh GUI: "
                            f"Mesh > {dimension}D)") from None


def _message(error: Exception) -> str:
    return " ".join(str(error).split()) or type(error).__name__

"""`pdemfem check` lines for coupled scenes: the DEM step, each solid's FE critical step, the sub-cycling."""
from __future__ import annotations

import math


def coupling_report(scene, base_dir, dt: float, comm=None) -> list:
    """Lines naming, per solid, the FE critical step and how the coupling covers a DEM step.

    Builds each solid (mesh, operators; no static solve): collective on `comm` (default COMM_SELF)."""
    if not scene.solids:
        return []
    from mpi4py import MPI

    from pdemfem.fem.solid import Solid

    comm = comm if comm is not None else MPI.COMM_SELF
    k = scene.coupling.fem_every
    interval = k * dt
    lines = [f"coupling: DEM dt = {dt:.3g} s; fem_every = {k}: the solids advance every {k} DEM step(s) "
             f"over {interval:.3g} s with the mean contact load"]
    for config in scene.solids:
        solid = Solid(config, scene.materials[config.material], gravity=scene.gravity, comm=comm, base_dir=base_dir)
        critical = solid.critical_time_step()
        substeps = max(1, math.ceil(interval / critical * (1.0 - 1e-12)))
        lines.append(f"solid {config.name}: {3 * solid.n_global_nodes} DOF ({config.element}, {config.mass} mass), "
                     f"FE critical step {critical:.3g} s = {critical / dt:.3g} x DEM dt -> {substeps} FE sub-step(s) "
                     f"of {interval / substeps:.3g} s per advance; contact groups {list(config.contact)}")
    return lines

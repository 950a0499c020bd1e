"""PETSc objects of one solid: MPIBAIJ (block size 3) stiffness and mass, ghosted vectors.

Every rank assembles its owned block rows from its local (owned + halo) cells
into a CSR in local column numbers, then hands PETSc the rows with global
columns in one setValuesBlockedCSR call; the preallocation is the CSR's exact
diagonal / off-diagonal counts, so no malloc happens during assembly.
"""
from __future__ import annotations

from dataclasses import dataclass

import numpy as np
from pdemfem.fem.petsc import PETSc

from pdemfem.fem.elements import ReferenceElement
from pdemfem.fem.kernels import assemble_owned_rows
from pdemfem.fem.partition import LocalMesh


@dataclass
class OwnedRowPattern:
    indptr: np.ndarray  # (n_owned + 1,)
    indices: np.ndarray  # local column numbers, ascending within a row
    diagonal_counts: np.ndarray  # owned columns per owned row (PETSc d_nnz)
    off_diagonal_counts: np.ndarray  # ghost columns per owned row (PETSc o_nnz)


def owned_row_pattern(cells: np.ndarray, n_owned: int, n_local: int) -> OwnedRowPattern:
    nen = cells.shape[1]
    rows = np.repeat(cells, nen, axis=1).ravel()
    cols = np.tile(cells, (1, nen)).ravel()
    keep = rows < n_owned
    keys = np.unique(rows[keep] * n_local + cols[keep])
    rows, cols = keys // n_local, keys % n_local
    indptr = np.concatenate([[0], np.cumsum(np.bincount(rows, minlength=n_owned))]).astype(np.int64)
    diagonal = np.bincount(rows[cols < n_owned], minlength=n_owned)
    return OwnedRowPattern(indptr, cols.astype(np.int64), diagonal.astype(np.int64), (np.diff(indptr) - diagonal).astype(np.int64))


def _blocked_matrix(comm, mesh: LocalMesh, pattern: OwnedRowPattern, block_values: np.ndarray) -> PETSc.Mat:
    n = 3 * mesh.n_owned_nodes
    N = 3 * mesh.n_global_nodes
    matrix = PETSc.Mat().createBAIJ(
        size=((n, N), (n, N)),
        bsize=3,
        nnz=(pattern.diagonal_counts.astype(PETSc.IntType), pattern.off_diagonal_counts.astype(PETSc.IntType)),
        comm=comm,
    )
    matrix.setOption(PETSc.Mat.Option.NEW_NONZERO_ALLOCATION_ERR, True)
    columns = mesh.local_to_global[pattern.indices]
    # MatSetValuesBlocked reads one block row as a dense (3 x 3*ncols) array; column-oriented, that is
    # simply every 3x3 block stored transposed, one after the other.
    matrix.setOption(PETSc.Mat.Option.ROW_ORIENTED, False)
    matrix.setValuesBlockedCSR(
        pattern.indptr.astype(PETSc.IntType), columns.astype(PETSc.IntType),
        np.ascontiguousarray(block_values.transpose(0, 2, 1)).ravel(), PETSc.InsertMode.INSERT_VALUES,
    )
    matrix.setOption(PETSc.Mat.Option.ROW_ORIENTED, True)
    matrix.assemble()
    return matrix


@dataclass
class AssembledOperators:
    stiffness: PETSc.Mat
    consistent_mass: PETSc.Mat | None  # None when the lumped mass alone is asked for
    lumped_mass: PETSc.Vec  # HRZ (row sum for P1), one entry per dof
    pattern: OwnedRowPattern


def assemble_operators(comm, mesh: LocalMesh, element: ReferenceElement, lam: float, mu: float, rho: float,
                       want_consistent_mass: bool) -> AssembledOperators:
    pattern = owned_row_pattern(mesh.cells, mesh.n_owned_nodes, mesh.n_local_nodes)
    nnz = len(pattern.indices)
    k_values = np.zeros((nnz, 3, 3))
    m_values = np.zeros(nnz)
    lumped = np.zeros(mesh.n_owned_nodes)
    assemble_owned_rows(
        mesh.points, mesh.cells, mesh.n_owned_nodes, pattern.indptr, pattern.indices,
        element.stiffness_gradients, element.stiffness_weights, element.mass_values, element.mass_weights,
        lam, mu, rho, k_values, m_values, lumped,
    )
    stiffness = _blocked_matrix(comm, mesh, pattern, k_values)
    consistent = None
    if want_consistent_mass:
        consistent = _blocked_matrix(comm, mesh, pattern, m_values[:, None, None] * np.eye(3))
    lumped_vec = stiffness.createVecRight()
    lumped_vec.setArray(np.repeat(lumped, 3))
    return AssembledOperators(stiffness, consistent, lumped_vec, pattern)


def ghosted_vector(comm, mesh: LocalMesh, block_size: int) -> PETSc.Vec:
    """A Vec over owned nodes with the mesh's ghost nodes attached (local form: owned, then ghosts)."""
    return PETSc.Vec().createGhost(
        mesh.ghost_nodes.astype(PETSc.IntType), size=(block_size * mesh.n_owned_nodes, block_size * mesh.n_global_nodes),
        bsize=block_size, comm=comm,
    )


def local_values(vector: PETSc.Vec, block_size: int) -> np.ndarray:
    """Owned + ghost values (after a forward ghost update) as a (n_local, block_size) copy."""
    vector.ghostUpdate(addv=PETSc.InsertMode.INSERT_VALUES, mode=PETSc.ScatterMode.FORWARD)
    with vector.localForm() as local:
        return local.getArray(readonly=True).reshape(-1, block_size).copy()

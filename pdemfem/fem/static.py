"""Static solve K u = b with Dirichlet rows: KSP CG + GAMG, rigid-body near-nullspace, options prefix fem_.

Users tune the solver from the command line (-fem_ksp_type, -fem_pc_type,
-fem_ksp_rtol, -fem_ksp_monitor, ...); defaults are CG, GAMG, rtol 1e-10.
"""
from __future__ import annotations

from dataclasses import dataclass

import numpy as np
from pdemfem.fem.petsc import PETSc

from pdemfem.errors import SolverError

OPTIONS_PREFIX = "fem_"
DEFAULT_RTOL = 1e-10

_REASONS = {
    value: name for name, value in vars(PETSc.KSP.ConvergedReason).items() if name.isupper() and isinstance(value, int)
}


def reason_name(reason: int) -> str:
    return _REASONS.get(reason, str(reason))


@dataclass
class StaticResult:
    iterations: int
    residual_norm: float  # true residual ||b - K u|| of the constrained system
    rhs_norm: float
    reason: str
    condition_estimate: float  # of the preconditioned operator (CG's Lanczos estimate; nan if unavailable)
    ksp_type: str
    pc_type: str


def rigid_body_near_nullspace(coordinates: PETSc.Vec) -> PETSc.NullSpace:
    """Three translations and three rotations from nodal coordinates (a Vec with block size 3)."""
    return PETSc.NullSpace().createRigidBody(coordinates)


def is_diagonal(matrix: PETSc.Mat) -> bool:
    """Collective: no nonzero off-diagonal entry (||A||_F^2 equals the squared norm of its diagonal
    up to the round-off of summing the squares, 1e-12 relative)."""
    frobenius_squared = matrix.norm(PETSc.NormType.FROBENIUS) ** 2
    diagonal = matrix.getDiagonal()
    diagonal_squared = diagonal.norm() ** 2
    diagonal.destroy()
    return frobenius_squared - diagonal_squared <= 1e-12 * frobenius_squared


def make_static_solver(constrained_stiffness: PETSc.Mat, coordinates: PETSc.Vec) -> PETSc.KSP:
    constrained_stiffness.setNearNullSpace(rigid_body_near_nullspace(coordinates))
    ksp = PETSc.KSP().create(comm=constrained_stiffness.getComm())
    ksp.setOptionsPrefix(OPTIONS_PREFIX)
    ksp.setOperators(constrained_stiffness)
    ksp.setType(PETSc.KSP.Type.CG)
    # A fully clamped solid leaves a diagonal operator (every row a constrained identity row):
    # GAMG finds no graph to coarsen and fails its set-up on several ranks, while Jacobi solves it
    # exactly in one iteration.
    ksp.getPC().setType(PETSc.PC.Type.JACOBI if is_diagonal(constrained_stiffness) else PETSc.PC.Type.GAMG)
    ksp.setTolerances(rtol=DEFAULT_RTOL, atol=1e-50, max_it=2000)
    # The true (unpreconditioned) residual, so -fem_ksp_rtol bounds the force imbalance itself.
    ksp.setNormType(PETSc.KSP.NormType.UNPRECONDITIONED)
    ksp.setComputeSingularValues(True)
    ksp.setFromOptions()
    return ksp


def solve_static(ksp: PETSc.KSP, rhs: PETSc.Vec, solution: PETSc.Vec, where: str) -> StaticResult:
    """Solve; SolverError naming the reason when PETSc reports divergence or the residual is not small."""
    operator = ksp.getOperators()[0]
    ksp.solve(rhs, solution)
    reason = ksp.getConvergedReason()
    iterations = ksp.getIterationNumber()
    residual = rhs.duplicate()
    operator.mult(solution, residual)
    residual.aypx(-1.0, rhs)
    residual_norm = residual.norm()
    rhs_norm = rhs.norm()
    try:
        largest, smallest = ksp.computeExtremeSingularValues()
        condition = float(largest / smallest) if smallest > 0 else float("inf")
    except PETSc.Error:
        condition = float("nan")
    result = StaticResult(iterations, residual_norm, rhs_norm, reason_name(reason), condition, ksp.getType(), ksp.getPC().getType())
    finite = np.isfinite(residual_norm)
    if reason < 0 or not finite:
        raise SolverError(
            where=where,
            problem=(
                f"KSP {result.ksp_type} + PC {result.pc_type} failed: {result.reason} after {iterations} iterations "
                f"(residual {residual_norm:.3e}, right-hand side {rhs_norm:.3e})"
            ),
            fix=(
                "make sure fixed/prescribed groups remove all six rigid-body motions (a free or under-supported solid is "
                "singular); or try -fem_ksp_type preonly -fem_pc_type lu on one rank to check the model"
            ),
        )
    return result

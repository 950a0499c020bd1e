"""Critical time step of explicit central difference from a proven element eigenvalue bound.

For K = sum_e K_e and M = sum_e M_e (consistent, or lumped element by element,
which is how the HRZ / row-sum diagonal is built), the Rayleigh quotient gives

    lambda_max(K, M) = max_x sum_e x_e^T K_e x_e / sum_e x_e^T M_e x_e <= max_e lambda_max(K_e, M_e),

so omega_max <= sqrt(max_e lambda_e), and dt_crit = 2 / omega_max is never
overestimated (constraints only lower lambda_max).  With Rayleigh damping the
central-difference limit becomes dt = (2 / omega) (sqrt(1 + xi^2) - xi) with
xi = alpha / (2 omega) + beta omega / 2 evaluated at omega_max.
"""
from __future__ import annotations

import numpy as np

from pdemfem.fem.elements import ReferenceElement
from pdemfem.fem.kernels import element_matrices

CHUNK = 4096  # cells per batched eigenvalue call (bounded memory)


def largest_element_eigenvalue(points, cells, n_cells, element: ReferenceElement, lam, mu, rho, lumped: bool) -> float:
    """max over cells [0, n_cells) of lambda_max(K_e, M_e) (M_e HRZ-lumped or consistent)."""
    nen = cells.shape[1]
    largest = 0.0
    for start in range(0, n_cells, CHUNK):
        ids = np.arange(start, min(n_cells, start + CHUNK), dtype=np.int64)
        k = np.empty((len(ids), 3 * nen, 3 * nen))
        m = np.empty((len(ids), nen, nen))
        ml = np.empty((len(ids), nen))
        element_matrices(points, cells, ids, element.stiffness_gradients, element.stiffness_weights,
                         element.mass_values, element.mass_weights, lam, mu, rho, k, m, ml)
        if lumped:
            scale = 1.0 / np.sqrt(np.repeat(ml, 3, axis=1))
            a = k * scale[:, :, None] * scale[:, None, :]
        else:
            chol = np.linalg.cholesky(np.kron(m, np.eye(3)))  # (m, 3nen, 3nen) lower factor
            inv = np.linalg.inv(chol)
            a = inv @ k @ np.swapaxes(inv, 1, 2)
        a = 0.5 * (a + np.swapaxes(a, 1, 2))
        largest = max(largest, float(np.linalg.eigvalsh(a)[:, -1].max()))
    return largest


def critical_step(omega_max: float, alpha: float, beta: float) -> float:
    if omega_max <= 0.0:
        return np.inf
    xi = alpha / (2.0 * omega_max) + beta * omega_max / 2.0
    return 2.0 / omega_max * (np.sqrt(1.0 + xi * xi) - xi)

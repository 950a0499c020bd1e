"""Numba kernels of the solid's heat conduction: conductivity rows, thermal coupling, the explicit update.

Same conventions as kernels.py: coords (n_local, 3), cells (n_cells, nen) in local node numbers,
only owned rows (local number < n_owned) are written.
"""
from __future__ import annotations

import numpy as np
from numba import njit

from pdemfem.fem.kernels import _find, cell_jacobian_inverse, physical_gradients


@njit(cache=True)
def assemble_conductivity_rows(coords, cells, n_owned, indptr, indices, stiff_grads, stiff_weights, conductivity, values):
    """Add every local cell's conductivity matrix k int grad N_a . grad N_b dV into the owned-row CSR values.

    The stiffness rule (degree 2(p-1)) integrates the product of two gradients exactly.
    """
    nen = cells.shape[1]
    jinv = np.empty((3, 3))
    g = np.empty((nen, 3))
    for c in range(cells.shape[0]):
        det = cell_jacobian_inverse(coords, cells, c, jinv)
        for q in range(stiff_weights.shape[0]):
            physical_gradients(stiff_grads[q], jinv, g)
            wq = stiff_weights[q] * det * conductivity
            for a in range(nen):
                row = cells[c, a]
                if row >= n_owned:
                    continue
                for b in range(nen):
                    pos = _find(indices, indptr[row], indptr[row + 1], cells[c, b])
                    values[pos] += wq * (g[a, 0] * g[b, 0] + g[a, 1] * g[b, 1] + g[a, 2] * g[b, 2])


@njit(cache=True)
def explicit_heat_update(temperature, conducted, capacity, source, conductance, fixed, fixed_values, dt, reaction):
    """One forward-Euler step on the owned nodes (flat arrays), in place.

    conducted = K T (conduction out of each node), source = flux + h A T_ambient + nodal heat flows [W],
    conductance = h A [W/K] (convection, lumped on the nodes).  A free node gets
    C dT = dt (source - conducted - conductance T); a fixed node is set to its value, and reaction
    receives the heat its reservoir supplied over the step: C (T_fixed - T) - dt (source - conducted -
    conductance T) (what the free update would have put in is then balanced exactly).
    """
    for i in range(temperature.shape[0]):
        rate = source[i] - conducted[i] - conductance[i] * temperature[i]
        if fixed[i]:
            reaction[i] = capacity[i] * (fixed_values[i] - temperature[i]) - dt * rate
            temperature[i] = fixed_values[i]
        else:
            reaction[i] = 0.0
            temperature[i] += dt * rate / capacity[i]


@njit(cache=True)
def assemble_thermal_coupling_rows(coords, cells, n_owned, indptr, indices, mass_values, mass_grads, mass_weights,
                                   coupling, mass):
    """The thermal load and energy as matrices, on the owned-row CSR (mass rule: exact for both):

    coupling[pos, d] += int grad_d N_a N_b dV   (thermal load f_a = 3 K alpha sum_b coupling_ab dT_b)
    mass[pos] += int N_a N_b dV                 (thermal energy 9/2 K alpha^2 dT . mass dT)
    """
    nen = cells.shape[1]
    jinv = np.empty((3, 3))
    g = np.empty((nen, 3))
    for c in range(cells.shape[0]):
        det = cell_jacobian_inverse(coords, cells, c, jinv)
        for q in range(mass_weights.shape[0]):
            physical_gradients(mass_grads[q], jinv, g)
            wq = mass_weights[q] * det
            for a in range(nen):
                row = cells[c, a]
                if row >= n_owned:
                    continue
                for b in range(nen):
                    pos = _find(indices, indptr[row], indptr[row + 1], cells[c, b])
                    weight = wq * mass_values[q, b]
                    mass[pos] += weight * mass_values[q, a]
                    for d in range(3):
                        coupling[pos, d] += weight * g[a, d]

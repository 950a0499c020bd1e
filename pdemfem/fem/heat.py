"""Transient heat conduction in one solid: C dT/dt = -K T + boundary and nodal heat flows.

    C_i = c m_i            lumped heat capacity [J/K] (the HRZ lumped mass m_i times the specific heat c)
    K_ab = int k grad N_a . grad N_b dV     conductivity matrix [W/K] (exact quadrature)
    flux:        q int N_a dA               into the solid [W]
    convection:  h int N_a dA (T_amb - T_a) lumped on the nodes [W]
    fixed:       T_a = T_fixed; the heat the group's reservoir supplies is booked as its reaction

Schemes (ThermalConfig.scheme):

- explicit: forward Euler with the lumped C, sub-stepped below dt_crit = 2 / lambda_max(C^-1 (K + H)),
  lambda_max bounded from above by Gershgorin's theorem on the assembled rows (never too large a step);
- implicit: (C/dt + theta (K + H)) T+ = (C/dt - (1 - theta)(K + H)) T + f, one step per advance, CG with
  Jacobi (steps up to JACOBI_RATIO explicit limits: the capacity dominates) or GAMG, assembled once per dt.

Heat is conserved exactly: every flow is booked per boundary entry (fixed groups by their reaction),
so sum_i C_i T_i changes by the booked heat to round-off.  The implicit solve's error would break that at
its tolerance; a uniform shift of the free nodes' temperatures makes their residuals sum to zero
(the solve's error stays a redistribution of heat, never a source).
"""
from __future__ import annotations

import math

import numpy as np
from mpi4py import MPI
from pdemfem.fem.petsc import PETSc

from pdemfem import state_dict as kinds
from pdemfem.errors import SolverError
from pdemfem.fem.assemble import owned_row_pattern
from pdemfem.fem.config import ThermalConfig
from pdemfem.fem.heat_kernels import assemble_conductivity_rows, assemble_thermal_coupling_rows, explicit_heat_update
from pdemfem.fem.kernels import face_node_areas
from pdemfem.fem.static import is_diagonal

OPTIONS_PREFIX = "fem_heat_"
# Implicit solve tolerance (relative residual): the temperature error it leaves is ~1e-10 of the
# temperature scale, far below the scheme's own truncation error; heat is conserved regardless.
HEAT_SOLVE_RTOL = 1e-10
# Up to this many explicit limits (dt lambda_max <= 2 JACOBI_RATIO) the capacity term dominates the
# implicit operator: its condition number is <= 1 + dt lambda_max, so CG + Jacobi needs few iterations
# and GAMG's set-up would cost more than it saves.  Above it GAMG keeps the iterations mesh-independent.
JACOBI_RATIO = 10.0


class SolidHeat:
    """The heat equation of one Solid (owned by it as solid.heat; see the module docstring)."""

    def __init__(self, solid, config: ThermalConfig, conductivity: float, heat_capacity: float):
        self.config = config
        self.comm = solid.comm
        self.name = solid.name
        self.scheme = config.scheme
        self.theta = float(config.theta)
        mesh = solid.mesh
        self.mesh = mesh
        self.temperature_vec = solid.temperature_vec
        n = mesh.n_owned_nodes
        self.n_owned_nodes = n
        self.capacity = heat_capacity * solid.lumped_mass.getArray(readonly=True)[::3].copy()
        self.conductivity_matrix = self._assemble_conductivity(solid, conductivity)
        self.conducted_vec = self.conductivity_matrix.createVecLeft()  # K T
        self.coupling_matrix = self.energy_matrix = None
        if solid._thermal_load_coefficient != 0.0:
            self._assemble_thermal_coupling(solid)
        self.nodal_heat_vec = self.conductivity_matrix.createVecLeft()  # heat flows for the next advance [W]
        self.nodal_heat_vec.zeroEntries()

        # Boundary entries, each with its own book (J through it since construction).
        self.book_names = []
        self._book_of = {}
        self.fixed = np.zeros(n, dtype=np.bool_)
        self.fixed_values = np.zeros(n)
        self.fixed_book = np.full(n, -1, dtype=np.int64)
        for entry in config.fixed:
            book = self._book("fixed", entry.group)
            nodes = mesh.group_nodes[entry.group]
            new = nodes[~self.fixed[nodes]]  # a node in several fixed groups keeps the first one's temperature
            self.fixed[new] = True
            self.fixed_values[new] = entry.temperature
            self.fixed_book[new] = book
        self.constant_source = np.zeros(n)  # flux loads + h A T_ambient [W]
        self.flux_books = []  # (book, local power [W])
        for entry in config.flux:
            load = entry.flux * self._node_areas(entry.group)
            self.constant_source += load
            self.flux_books.append((self._book("flux", entry.group), float(load.sum())))
        self.conductance = np.zeros(n)  # h A [W/K]
        self.convection_books = []  # (book, h A per node, ambient)
        for entry in config.convection:
            conductance = entry.coefficient * self._node_areas(entry.group)
            self.conductance += conductance
            self.constant_source += conductance * entry.ambient
            self.convection_books.append((self._book("convection", entry.group), conductance, float(entry.ambient)))
        # Books [J] per boundary entry and the heat put in through add_nodal_heat: global totals up to the last
        # read, plus this rank's part since (summed over the ranks only when read: no reduction per advance).
        self._booked_total = np.zeros(len(self.book_names) + 1)
        self._booked_local = np.zeros(len(self.book_names) + 1)

        self._eigenvalue_bound = None
        self._implicit_dt = None
        self._full_operator = None
        self._solver = None
        self._free_column_sums = None
        self._work_vecs = None  # implicit: held values, right-hand side, solution, residual
        self._reaction = np.zeros(n)
        # The fixed groups hold their temperature from the start.
        if self.fixed.any():
            values = self.temperature_vec.getArray()
            values[self.fixed] = self.fixed_values[self.fixed]

    # ------------------------------------------------------------ set-up
    def _book(self, kind: str, group: str) -> int:
        name = f"{kind}_{group}"
        if name not in self._book_of:
            self._book_of[name] = len(self.book_names)
            self.book_names.append(name)
        return self._book_of[name]

    def _node_areas(self, group: str) -> np.ndarray:
        areas = np.zeros(self.n_owned_nodes)
        face_node_areas(self.mesh.points, self.mesh.group_faces[group], self.n_owned_nodes, areas)
        return areas

    def _assemble_conductivity(self, solid, conductivity: float) -> PETSc.Mat:
        mesh, element = self.mesh, solid.element
        pattern = owned_row_pattern(mesh.cells, mesh.n_owned_nodes, mesh.n_local_nodes)
        values = np.zeros(len(pattern.indices))
        assemble_conductivity_rows(mesh.points, mesh.cells, mesh.n_owned_nodes, pattern.indptr, pattern.indices,
                                   element.stiffness_gradients, element.stiffness_weights, float(conductivity), values)
        self._pattern = pattern
        n, total = mesh.n_owned_nodes, mesh.n_global_nodes
        matrix = PETSc.Mat().createAIJ(
            size=((n, total), (n, total)),
            nnz=(pattern.diagonal_counts.astype(PETSc.IntType), pattern.off_diagonal_counts.astype(PETSc.IntType)),
            comm=self.comm)
        matrix.setOption(PETSc.Mat.Option.NEW_NONZERO_ALLOCATION_ERR, True)
        matrix.setValuesCSR(pattern.indptr.astype(PETSc.IntType),
                            mesh.local_to_global[pattern.indices].astype(PETSc.IntType), values)
        matrix.assemble()
        # The owned rows are complete here (halo cells included): their absolute sums bound lambda_max.
        self._absolute_row_sums = np.add.reduceat(np.abs(values), pattern.indptr[:-1]) if n else np.zeros(0)
        return matrix

    def _assemble_thermal_coupling(self, solid) -> None:
        """The thermal load G dT and energy dT.M dT as matrices: each refresh is then two products instead of an
        integration over every cell (which cost ~10 mechanical advances per refresh on P1, more on P2)."""
        mesh, element, pattern = self.mesh, solid.element, self._pattern
        nnz = len(pattern.indices)
        coupling = np.zeros((nnz, 3))
        mass = np.zeros(nnz)
        assemble_thermal_coupling_rows(mesh.points, mesh.cells, mesh.n_owned_nodes, pattern.indptr, pattern.indices,
                                       element.mass_values, element.mass_gradients, element.mass_weights, coupling, mass)
        n, total = mesh.n_owned_nodes, mesh.n_global_nodes
        columns = mesh.local_to_global[pattern.indices].astype(PETSc.IntType)
        # Three rows (x, y, z) per node, each with the node's columns: order the entries by (node, axis, column).
        node_of_entry = np.repeat(np.arange(n), np.diff(pattern.indptr))
        entries, axes = np.tile(np.arange(nnz), 3), np.repeat(np.arange(3), nnz)
        order = np.lexsort((entries, axes, np.tile(node_of_entry, 3)))
        entries, axes = entries[order], axes[order]
        row_pointers = np.concatenate([[0], np.cumsum(np.repeat(np.diff(pattern.indptr), 3))])
        load = PETSc.Mat().createAIJ(
            size=((3 * n, 3 * total), (n, total)),
            nnz=(np.repeat(pattern.diagonal_counts, 3).astype(PETSc.IntType),
                 np.repeat(pattern.off_diagonal_counts, 3).astype(PETSc.IntType)), comm=self.comm)
        load.setValuesCSR(row_pointers.astype(PETSc.IntType), columns[entries],
                          solid._thermal_load_coefficient * coupling[entries, axes])
        load.assemble()
        energy = self.conductivity_matrix.duplicate(copy=False)
        energy.setValuesCSR(pattern.indptr.astype(PETSc.IntType), columns, solid._thermal_energy_coefficient * mass)
        energy.assemble()
        self.coupling_matrix, self.energy_matrix = load, energy
        self._delta_vec = self.conducted_vec.duplicate()

    def thermal_load(self, reference_temperature: float, load_vec: PETSc.Vec) -> float:
        """Collective: load_vec = G (T - T_ref); returns the thermal energy int 9/2 K alpha^2 dT^2 dV [J]."""
        self._delta_vec.setArray(self.temperature_vec.getArray(readonly=True) - reference_temperature)
        self.coupling_matrix.mult(self._delta_vec, load_vec)
        self.energy_matrix.mult(self._delta_vec, self.conducted_vec)
        return self.conducted_vec.dot(self._delta_vec)

    # ------------------------------------------------------------ stability
    def largest_eigenvalue_bound(self) -> float:
        """Collective: upper bound of lambda_max(C^-1 (K + H)) [1/s]: by Gershgorin's theorem (C^-1 (K + H) is
        similar to a symmetric matrix, so its eigenvalues are real and lie in the row discs)
        max_i (sum_j |K_ij| + H_i) / C_i."""
        if self._eigenvalue_bound is None:
            local = 0.0
            if self.n_owned_nodes:
                local = float(np.max((self._absolute_row_sums + self.conductance) / self.capacity))
            self._eigenvalue_bound = self.comm.allreduce(local, op=MPI.MAX)
        return self._eigenvalue_bound

    def critical_time_step(self) -> float:
        """Collective: the largest stable forward-Euler step 2 / lambda_max [s] (never above the true one)."""
        bound = self.largest_eigenvalue_bound()
        return math.inf if bound <= 0.0 else 2.0 / bound

    # ------------------------------------------------------------ heat flows
    def add_nodal_heat(self, global_node_indices, heat_flows) -> None:
        """Not collective: heat flows [W] into nodes of any rank, applied over the next advance, then cleared."""
        indices = np.asarray(global_node_indices, dtype=PETSc.IntType).ravel()
        if len(indices):
            flows = np.ascontiguousarray(heat_flows, dtype=float).reshape(len(indices))
            self.nodal_heat_vec.setValues(indices, flows, PETSc.InsertMode.ADD_VALUES)

    def thermal_energy(self) -> float:
        """Collective: sum_i C_i T_i [J] (heat content above 0 K with the lumped capacity)."""
        local = float(np.dot(self.capacity, self.temperature_vec.getArray(readonly=True)))
        return self.comm.allreduce(local, op=MPI.SUM)

    def _settle_books(self) -> np.ndarray:
        """Collective: the books' global totals (this rank's parts since the last read summed in)."""
        local = self._booked_local.copy()
        if self.comm.size > 1:
            self.comm.Allreduce(MPI.IN_PLACE, local, op=MPI.SUM)
        self._booked_total += local
        self._booked_local[:] = 0.0
        return self._booked_total

    @property
    def booked(self) -> np.ndarray:
        """Collective: heat [J] in through each boundary entry since construction (book_names order)."""
        return self._settle_books()[:-1].copy()

    @property
    def nodal_heat_added(self) -> float:
        """Collective: heat [J] put in through add_nodal_heat since construction."""
        return float(self._settle_books()[-1])

    def boundary_heat(self) -> dict:
        """Collective: heat [J] that entered through each boundary entry since construction, keyed
        '<kind>_<group>' (kind fixed, flux or convection; negative: heat left)."""
        booked = self.booked
        return {name: float(booked[book]) for book, name in enumerate(self.book_names)}

    # ------------------------------------------------------------ advance
    def advance(self, interval: float) -> tuple:
        """Collective: advance the temperatures over `interval` with the nodal heat added since the last
        advance (constant over it); returns the steps taken.  No reduction: the books stay rank-local until
        read (booked, boundary_heat, nodal_heat_added)."""
        self.nodal_heat_vec.assemble()
        nodal = self.nodal_heat_vec.getArray(readonly=True).copy()
        self.nodal_heat_vec.zeroEntries()
        source = self.constant_source + nodal
        local = self._booked_local  # books, then the nodal heat
        if self.scheme == "explicit":
            steps = max(1, math.ceil(interval / self.critical_time_step() * (1.0 - 1e-12)))
            dt = interval / steps
            for _ in range(steps):
                self._explicit_step(dt, source, local)
                local[-1] += dt * nodal.sum()
        else:
            steps = 1
            self._implicit_step(interval, source, local)
            local[-1] += interval * nodal.sum()
        return steps

    def _book_constant_and_convection(self, dt: float, temperature: np.ndarray, local: np.ndarray) -> None:
        for book, power in self.flux_books:
            local[book] += dt * power
        for book, conductance, ambient in self.convection_books:
            local[book] += dt * (ambient * conductance.sum() - float(np.dot(conductance, temperature)))

    def _book_reactions(self, local: np.ndarray) -> None:
        if self.fixed.any():
            local[: len(self.book_names)] += np.bincount(self.fixed_book[self.fixed], weights=self._reaction[self.fixed],
                                                         minlength=len(self.book_names))

    def _explicit_step(self, dt: float, source: np.ndarray, local: np.ndarray) -> None:
        self.conductivity_matrix.mult(self.temperature_vec, self.conducted_vec)
        temperature = self.temperature_vec.getArray()
        self._book_constant_and_convection(dt, temperature, local)
        explicit_heat_update(temperature, self.conducted_vec.getArray(readonly=True), self.capacity, source,
                             self.conductance, self.fixed, self.fixed_values, dt, self._reaction)
        self._book_reactions(local)

    def _implicit_operators(self, dt: float) -> None:
        if self._implicit_dt == dt:
            return
        theta = self.theta
        full = self.conductivity_matrix.duplicate(copy=True)
        full.scale(theta)
        diagonal = self.conducted_vec.duplicate()
        diagonal.setArray(self.capacity / dt + theta * self.conductance)
        full.setDiagonal(diagonal, addv=PETSc.InsertMode.ADD_VALUES)
        constrained = full.duplicate(copy=True)
        first = full.getOwnershipRange()[0]
        constrained.zeroRowsColumns((first + np.flatnonzero(self.fixed)).astype(PETSc.IntType), 1.0)
        if self._solver is None:
            self._solver = PETSc.KSP().create(comm=self.comm)
            self._solver.setOptionsPrefix(OPTIONS_PREFIX)
            self._solver.setType(PETSc.KSP.Type.CG)
            self._solver.setTolerances(rtol=HEAT_SOLVE_RTOL, atol=1e-300, max_it=5000)
            self._solver.setInitialGuessNonzero(True)  # the current temperatures
        ratio = dt * self.largest_eigenvalue_bound() / 2.0  # dt in explicit limits
        # With every neighbour of every free node fixed the operator is diagonal: GAMG finds no graph to
        # coarsen (its set-up fails on several ranks), while Jacobi is exact.
        jacobi = ratio <= JACOBI_RATIO or is_diagonal(constrained)
        self._solver.getPC().setType(PETSc.PC.Type.JACOBI if jacobi else PETSc.PC.Type.GAMG)
        self._solver.setOperators(constrained)
        self._solver.setFromOptions()
        # (A 1_free) on every row: the residual change of a uniform shift of the free temperatures.
        free = diagonal.duplicate()
        free.setArray((~self.fixed).astype(float))
        self._free_column_sums = diagonal.duplicate()
        full.mult(free, self._free_column_sums)
        self._full_operator = full
        self._implicit_dt = dt
        if self._work_vecs is None:
            self._work_vecs = tuple(self.conducted_vec.duplicate() for _ in range(4))

    def _implicit_step(self, dt: float, source: np.ndarray, local: np.ndarray) -> None:
        self._implicit_operators(dt)
        theta = self.theta
        temperature = self.temperature_vec.getArray(readonly=True).copy()
        self.conductivity_matrix.mult(self.temperature_vec, self.conducted_vec)
        explicit_part = self.conducted_vec.getArray(readonly=True) + self.conductance * temperature
        rhs_values = self.capacity / dt * temperature - (1.0 - theta) * explicit_part + source
        # Dirichlet rows: the fixed values move to the right-hand side (the operator stays symmetric).
        held, rhs, solution, residual_vec = self._work_vecs
        held.setArray(np.where(self.fixed, self.fixed_values, 0.0))
        self._full_operator.mult(held, rhs)
        constrained_rhs = rhs_values - rhs.getArray(readonly=True)
        constrained_rhs[self.fixed] = self.fixed_values[self.fixed]
        rhs.setArray(constrained_rhs)
        solution.setArray(np.where(self.fixed, self.fixed_values, temperature))
        self._solver.solve(rhs, solution)
        reason = self._solver.getConvergedReason()
        if reason < 0:
            raise SolverError(where=f"solid '{self.name}': implicit heat solve",
                              problem=f"CG + {self._solver.getPC().getType()} failed (reason {reason}) "
                                      f"after {self._solver.getIterationNumber()} iterations",
                              fix="use thermal.scheme: explicit, or pass -fem_heat_ksp_max_it / -fem_heat_pc_type")
        # Residual of the unconstrained rows: (A T+ - b)_i = C_i dT_i / dt - (net heat flow into i).
        self._full_operator.mult(solution, residual_vec)
        residual = residual_vec.getArray(readonly=True) - rhs_values
        free = ~self.fixed
        column_sums = self._free_column_sums.getArray(readonly=True)
        totals = np.array([residual[free].sum(), column_sums[free].sum()])
        self.comm.Allreduce(MPI.IN_PLACE, totals, op=MPI.SUM)
        new = solution.getArray(readonly=True).copy()
        if totals[1] > 0.0:
            shift = -totals[0] / totals[1]
            new[free] += shift
            residual = residual + shift * column_sums
        self._reaction[:] = np.where(self.fixed, dt * residual, 0.0)
        self._book_constant_and_convection(dt, theta * new + (1.0 - theta) * temperature, local)
        self._book_reactions(local)
        self.temperature_vec.setArray(new)

    # ------------------------------------------------------------ checkpoints
    def state_dict(self, nodes: np.ndarray) -> dict:
        """Collective: the books and the pending nodal heat (by input node number)."""
        self.nodal_heat_vec.assemble()
        totals = self._settle_books()
        return {"booked": kinds.scalar([float(value) for value in totals[:-1]]),
                "book_names": kinds.scalar(list(self.book_names)),
                "nodal_heat_added": kinds.scalar(float(totals[-1])),
                "pending": kinds.keyed_slab(self.nodal_heat_vec.getArray(readonly=True).copy(), nodes)}

    def load_state_dict(self, state: dict, nodes: np.ndarray) -> None:
        if list(state["book_names"]) != self.book_names:
            raise kinds.StateMismatch(f"solid '{self.name}' books heat through {self.book_names}, the checkpoint "
                                      f"through {list(state['book_names'])}")
        self._booked_total[:-1] = np.array(state["booked"], dtype=float).reshape(len(self.book_names))
        self._booked_total[-1] = float(state["nodal_heat_added"])
        self._booked_local[:] = 0.0
        self.nodal_heat_vec.setArray(np.ascontiguousarray(np.asarray(state["pending"])[nodes]))

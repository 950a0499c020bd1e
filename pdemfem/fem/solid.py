"""One deformable solid: built from its scene entry, advanced by the coupling loop.

    solid = Solid(config, material, gravity=(0, 0, -9.81), comm=MPI.COMM_WORLD, base_dir=scene_dir)
    solid.static_solve()                      # K u0 = b0, starts at rest in equilibrium
    dt_max = solid.critical_time_step()       # proven bound (see stability.py)
    solid.add_nodal_forces(nodes, forces)     # any rank, any node: particle contact forces
    solid.step(dt)                            # one explicit central-difference step
    solid.add_nodal_heat(nodes, flows)        # heat on (thermal: or heat=True): particle heat flows [W]
    solid.advance(interval)                   # sub-cycled mechanics, then the temperatures (heat.py)

All methods are collective unless stated otherwise; nodal arrays hold the nodes
this rank owns (global numbers solid.global_node_range), cell arrays the cells it owns.
"""
from __future__ import annotations

import logging
import math
from pathlib import Path

import numpy as np
from mpi4py import MPI
from pdemfem.fem.petsc import PETSc

from pdemfem import state_dict as kinds
from pdemfem.errors import MeshError, SceneError, SolverError
from pdemfem.fem import kernels
from pdemfem.fem.assemble import assemble_operators, ghosted_vector, local_values
from pdemfem.fem.config import SolidConfig, ThermalConfig
from pdemfem.fem.elements import reference_element
from pdemfem.fem.frame import (MovingFrame, centrifugal_reference_load, coriolis_correction, frame_load,
                               load_work)
from pdemfem.fem.mesh import load_mesh
from pdemfem.fem.partition import distribute_mesh
from pdemfem.fem.stability import critical_step, largest_element_eigenvalue
from pdemfem.fem.static import StaticResult, make_static_solver, solve_static
from pdemfem.fem.surface import ContactSurface

logger = logging.getLogger("pdemfem.fem")

MASS_SOLVE_PREFIX = "fem_mass_"
# Consistent-mass solve tolerance: relative error of the acceleration.  Central difference
# already errs by ~(omega dt)^2/24 per step in phase; for the modes that carry the physics
# (omega dt < 1e-2) that is ~1e-6, so 1e-8 keeps the solve below the integrator's own error.
MASS_SOLVE_RTOL = 1e-8
_NO_DAMPING_FORCE = np.zeros(0)  # the central-difference kernel's stiffness damping force without beta
BLOWUP_CHECK_EVERY = 16  # steps between the (cheap, one norm) divergence checks
# A node's contact dashpot, symmetric D (6) and target g (3), force g - D v; then its contact spring over the
# sub-steps, symmetric S (6), force -S (u - u0) with u0 its displacement at the start of the advance.
DAMPER_COLUMNS = 15


def _sum(comm, value: float) -> float:
    buffer = np.array([value], dtype=np.float64)
    comm.Allreduce(MPI.IN_PLACE, buffer, op=MPI.SUM)
    return float(buffer[0])


def _heat_properties(config: SolidConfig, material) -> tuple:
    """(conductivity, heat_capacity) of a solid that conducts heat; SceneError naming the missing key."""
    examples = {"conductivity": "W/(m K); steel ~50, rubber ~0.15", "heat_capacity": "J/(kg K); steel ~490, rubber ~2000"}
    for key, example in examples.items():
        if getattr(material, key, None) is None:
            raise SceneError(
                f"materials.{config.material}.{key}",
                f"solid '{config.name}' conducts heat (its thermal: key or the scene's heat switch) but its material "
                f"has no {key}",
                f"add {key}: <value> [{example}] to materials.{config.material}, or turn heat off for this solid")
    return float(material.conductivity), float(material.heat_capacity)


def _raise_thermal_group_error(name: str, error: MeshError, mechanical_groups, thermal_groups) -> None:
    """Re-raise a mesh group error as a SceneError naming the thermal key when only that key names the group."""
    for kind, index, group in thermal_groups:
        if error.where.endswith(f"group '{group}'") and group not in mechanical_groups:
            raise SceneError(f"solids ({name}).thermal.{kind}[{index}].group", f"{error.where}: {error.problem}",
                             error.fix) from None
    raise error


class Solid(kinds.StateComponent):
    def __init__(self, config: SolidConfig, material, gravity=(0.0, 0.0, -9.81), comm=MPI.COMM_WORLD, base_dir=Path("."),
                 heat: bool = False):
        """heat=True (the scene's heat switch) or a `thermal:` entry turn heat conduction on (solid.heat);
        otherwise solid.heat is None and the temperature changes only through set_temperature."""
        self.config = config
        self.material = material
        self.comm = comm
        self.name = config.name
        E, nu = material.youngs_modulus, material.poisson_ratio
        self.density = material.density
        self.lam = E * nu / ((1.0 + nu) * (1.0 - 2.0 * nu))
        self.mu = E / (2.0 * (1.0 + nu))
        bulk = self.lam + 2.0 * self.mu / 3.0
        alpha_t = material.thermal_expansion
        self._thermal_load_coefficient = 3.0 * bulk * alpha_t  # sigma_th = -3 K alpha dT I
        self._thermal_energy_coefficient = 4.5 * bulk * alpha_t * alpha_t  # 1/2 eps_th : D : eps_th / dT^2
        self.element = reference_element(config.element)
        self.lumped = config.mass == "lumped"
        self.damping_alpha, self.damping_beta = config.damping.alpha, config.damping.beta
        motion = getattr(config, "motion", None)
        # A prescribed rigid motion the solid deforms relative to (frame.py); None: a fixed frame.
        self.frame = (MovingFrame(motion.axis_point, motion.angular_velocity, motion.velocity, motion.carried_mass,
                                  motion.start) if motion is not None else None)

        thermal = config.thermal if config.thermal is not None else (ThermalConfig() if heat else None)
        if thermal is not None:
            properties = _heat_properties(config, material)
        groups = list(config.fixed) + [p.group for p in config.prescribed] + [t.group for t in config.tractions]
        thermal_groups = [] if thermal is None else thermal.groups()
        try:
            self.mesh = distribute_mesh(
                comm, lambda: load_mesh(config.mesh, Path(base_dir)), config.element,
                groups + [group for _, _, group in thermal_groups], list(config.contact),
                [p.point for p in config.point_forces],
                regions=config.regions, region_key=f"solids ({config.name})",
            )
        except MeshError as error:
            _raise_thermal_group_error(config.name, error, groups, thermal_groups)
        mesh = self.mesh
        self.n_owned_nodes = mesh.n_owned_nodes
        self.global_node_range = mesh.node_range
        self.n_global_nodes = mesh.n_global_nodes

        operators = assemble_operators(comm, mesh, self.element, self.lam, self.mu, self.density, not self.lumped)
        self.stiffness = operators.stiffness
        self.consistent_mass = operators.consistent_mass
        self.lumped_mass = operators.lumped_mass
        self._inverse_lumped_mass = 1.0 / self.lumped_mass.getArray(readonly=True).copy()

        self.displacement_vec = ghosted_vector(comm, mesh, 3)
        self.velocity_vec = self.stiffness.createVecRight()  # v^{n+1/2}: the velocity over the last step
        self.acceleration_vec = self.stiffness.createVecRight()
        self.internal_force_vec = self.stiffness.createVecRight()  # K (u + beta v) at the last force evaluation
        self.load_vec = self.stiffness.createVecRight()  # total applied load at the last force evaluation
        self.constant_load_vec = self.stiffness.createVecRight()  # gravity + tractions + point forces
        self.thermal_load_vec = self.stiffness.createVecRight()
        self.nodal_force_vec = self.stiffness.createVecRight()  # external (contact) forces for the next step
        # Contact dashpots for the next advance, per node (D_xx, D_yy, D_zz, D_yz, D_xz, D_xy, g_x, g_y, g_z).
        self.damper_vec = PETSc.Vec().createMPI((DAMPER_COLUMNS * self.n_owned_nodes, PETSc.DECIDE),
                                                bsize=DAMPER_COLUMNS, comm=comm)
        self.damper_vec.zeroEntries()
        self._damped_nodes = np.zeros(0, dtype=np.int64)
        self._dampers = np.zeros((0, DAMPER_COLUMNS))
        # The contact springs of the advance in progress (coupling/dampers.py): their rows among the damped nodes,
        # the displacements at the start of the advance, and the time integral of the displacement since then over
        # the sub-steps (per owned node in spring_integral_vec after the advance, gathered by the coupled surface).
        self._spring_rows = np.zeros(0, dtype=np.int64)
        self._spring_start = np.zeros((0, 3))
        self._spring_integral = np.zeros((0, 3))
        self.spring_integral_vec = self.stiffness.createVecRight()
        self.spring_integral_vec.zeroEntries()
        self.springs_integrated = False  # the last advance took several sub-steps (same on every rank)
        self._lumped_mass_values = self.lumped_mass.getArray(readonly=True).copy()
        self.damper_work_local = 0.0  # work of the contact dashpots on this rank's nodes since construction [J]
        self._base_load_vec = self.stiffness.createVecRight()  # constant + thermal
        self._work_vec = self.stiffness.createVecRight()
        # beta K v- (stiffness damping), and M v-bar for the work of alpha damping with consistent mass.
        self._stiffness_damping_vec = self.stiffness.createVecRight()
        self.coordinates_vec = self.stiffness.createVecRight()
        self.coordinates_vec.setArray(mesh.points[: self.n_owned_nodes].ravel())
        self.temperature_vec = ghosted_vector(comm, mesh, 1)
        if self.frame is not None:
            self._frame_load_vec = self.stiffness.createVecRight()  # gravity turned into the frame + centrifugal
            self._frame_base_vec = self.stiffness.createVecRight()  # base load + frame load of the step
            self._centrifugal_reference = np.zeros(3 * self.n_owned_nodes)
            self._no_centrifugal_load = np.zeros(3 * self.n_owned_nodes)  # before motion.start
            centrifugal_reference_load(mesh.points, mesh.cells, self.n_owned_nodes, self.element.mass_values,
                                       self.element.mass_weights, self.density, self.frame.angular_velocity,
                                       self.frame.axis_point, self._centrifugal_reference)
            # Work the frame fed into the elastic motion through its loads, this rank's since the last reading,
            # and the sum over the ranks up to it [J] (frame.py: contact work is booked by the coupled surface).
            self.frame_work_local = 0.0
            self._frame_work_summed = 0.0

        self._constrained = np.zeros(3 * self.n_owned_nodes, dtype=np.bool_)
        self._prescribed_displacement = np.zeros(3 * self.n_owned_nodes)
        self._prescribed_velocity = np.zeros(3 * self.n_owned_nodes)
        for entry in config.prescribed:
            values = entry.velocity if entry.velocity is not None else entry.displacement
            target = self._prescribed_velocity if entry.velocity is not None else self._prescribed_displacement
            nodes = mesh.group_nodes[entry.group]
            for d, value in enumerate(values):
                if value is not None:
                    self._constrained[3 * nodes + d] = True
                    self._prescribed_displacement[3 * nodes + d] = 0.0
                    self._prescribed_velocity[3 * nodes + d] = 0.0
                    target[3 * nodes + d] = value
        for group in config.fixed:  # fixed wins where a node is in both kinds of group
            dofs = (3 * mesh.group_nodes[group][:, None] + np.arange(3)).ravel()
            self._constrained[dofs] = True
            self._prescribed_displacement[dofs] = 0.0
            self._prescribed_velocity[dofs] = 0.0

        self.time = 0.0
        self.step_count = 0
        # Work of applied loads and supports since construction [J]: the sum over the ranks up to the last
        # reading, and this rank's work since (a step makes no reduction for it: read it at output).
        self._external_work_summed = 0.0
        self._external_work_local = 0.0
        self._support_work_summed = 0.0
        self._support_work_local = 0.0
        self._support_half_step = 0.0  # this rank's: the supports' work over the second half of the last step
        self._damping_work_summed = 0.0  # the Rayleigh damping's work, as the external work's
        self._damping_work_local = 0.0
        self._thermal_energy = 0.0
        self.heat = None  # the heat equation (heat.SolidHeat) when this solid conducts heat
        self.thermoelastic_work = 0.0  # strain energy the temperature changes of the heat path put in [J]
        self._critical_step = None
        self._corner_volumes = None  # the owned cells' undeformed corner-tetrahedron volumes (smallest_volume_ratio)
        self._omega_bound = None
        self._static_solver = None
        self._mass_solver = None
        self._surfaces = {}
        # Small-strain displacements larger than the body itself only come from an unstable step.
        self._diameter = float(np.linalg.norm(mesh.bounding_box[1] - mesh.bounding_box[0]))
        self._divergence_threshold = self._diameter

        self.set_gravity(gravity)
        initial, reference = config.temperatures()
        self.reference_temperature = 293.15 if reference is None else reference
        self.set_temperature(self.reference_temperature if initial is None else initial)
        if thermal is not None:
            from pdemfem.fem.heat import SolidHeat

            self.heat = SolidHeat(self, thermal, *properties)  # sets the fixed groups' temperatures
            self._refresh_thermal_load()
        self._set_velocity_from_constraints()

    # ------------------------------------------------------------------ loads
    def set_gravity(self, gravity) -> None:
        """Collective: rebuild the constant load (gravity, tractions, point forces) for a new gravity vector."""
        mesh = self.mesh
        load = np.zeros((self.n_owned_nodes, 3))
        if self.frame is None:
            body = self.density * np.asarray(gravity, dtype=float)
            kernels.body_force_load(mesh.points, mesh.cells, self.n_owned_nodes, self.element.mass_values,
                                    self.element.mass_weights, body, load)
        else:
            # Gravity turns in the moving frame: keep the nodal loads of a unit density force along each axis.
            self._gravity_unit_loads = np.zeros((3, 3 * self.n_owned_nodes))
            for axis in range(3):
                unit = np.zeros((self.n_owned_nodes, 3))
                kernels.body_force_load(mesh.points, mesh.cells, self.n_owned_nodes, self.element.mass_values,
                                        self.element.mass_weights, self.density * np.eye(3)[axis], unit)
                self._gravity_unit_loads[axis] = unit.ravel()
        for entry in self.config.tractions:
            areas = np.zeros(self.n_owned_nodes)
            kernels.face_node_areas(mesh.points, mesh.group_faces[entry.group], self.n_owned_nodes, areas)
            load += areas[:, None] * np.asarray(entry.traction, float)
        self.constant_load_vec.setArray(load.ravel())
        if self.comm.rank == 0 and len(self.config.point_forces):
            forces = np.array([p.force for p in self.config.point_forces], dtype=float)
            self.constant_load_vec.setValuesBlocked(mesh.point_nodes.astype(PETSc.IntType), forces.ravel(), PETSc.InsertMode.ADD_VALUES)
        self.constant_load_vec.assemble()
        self._update_base_load()
        self.gravity = tuple(float(g) for g in gravity)

    def set_temperature(self, nodal_temperatures) -> None:
        """Collective: nodal temperature [K] of the owned nodes (array (n_owned,) or a scalar); rebuilds the thermal load."""
        values = np.broadcast_to(np.asarray(nodal_temperatures, dtype=float), (self.n_owned_nodes,))
        self.temperature_vec.setArray(values)
        self._refresh_thermal_load()

    def _refresh_thermal_load(self) -> None:
        """Collective: the thermal load and its energy from the current temperatures."""
        if self.heat is not None and self.heat.coupling_matrix is not None:
            self._thermal_energy = self.heat.thermal_load(self.reference_temperature, self.thermal_load_vec)
            self._update_base_load()
            return
        delta_t = local_values(self.temperature_vec, 1)[:, 0] - self.reference_temperature
        load = np.zeros((self.n_owned_nodes, 3))
        energy = 0.0
        if self._thermal_load_coefficient != 0.0:
            energy = kernels.thermal_load(
                self.mesh.points, self.mesh.cells, self.n_owned_nodes, self.mesh.n_owned_cells, self.element.mass_values,
                self.element.mass_gradients, self.element.mass_weights, delta_t, self._thermal_load_coefficient,
                self._thermal_energy_coefficient, load,
            )
        self.thermal_load_vec.setArray(load.ravel())
        self._update_base_load()
        self._thermal_energy = _sum(self.comm, energy)

    def add_nodal_forces(self, global_node_indices, forces) -> None:
        """Not collective: add forces (n, 3) [N] on nodes of any rank; applied in the next step (or static solve), then cleared.

        World components; a solid with motion: turns them into its frame as it stands now (self.time)."""
        indices = np.asarray(global_node_indices, dtype=PETSc.IntType).ravel()
        forces = np.ascontiguousarray(forces, dtype=float).reshape(len(indices), 3)
        if self.frame is not None and len(indices):
            forces = np.ascontiguousarray(self.frame.vectors_to_body(forces, self.time))
        if len(indices):
            self.nodal_force_vec.setValuesBlocked(indices, forces.ravel(), PETSc.InsertMode.ADD_VALUES)

    # ------------------------------------------------------------------ heat
    def _heat_or_error(self):
        if self.heat is None:
            raise RuntimeError(f"solid '{self.name}' does not conduct heat (no thermal: key and heat=False)")
        return self.heat

    def add_nodal_heat(self, global_node_indices, heat_flows) -> None:
        """Not collective: heat flows (n,) [W] into nodes of any rank (like add_nodal_forces), held constant over
        the next advance (or step), then cleared: the solid receives exactly sum(heat_flows) * interval [J]."""
        self._heat_or_error().add_nodal_heat(global_node_indices, heat_flows)

    def thermal_energy(self) -> float:
        """Collective: heat content sum_i C_i T_i [J] (lumped capacity C_i = c m_i, T in K, relative to 0 K)."""
        return self._heat_or_error().thermal_energy()

    def boundary_heat(self) -> dict:
        """Collective: heat [J] that entered through each thermal boundary entry since construction,
        keyed '<kind>_<group>' (fixed_<g>, flux_<g>, convection_<g>; negative: the heat left)."""
        return self._heat_or_error().boundary_heat()

    @property
    def nodal_heat_added(self) -> float:
        """Collective: heat [J] put in through add_nodal_heat since construction."""
        return self._heat_or_error().nodal_heat_added

    def heat_critical_time_step(self) -> float:
        """Collective: the explicit heat scheme's stability limit 2 / lambda_max(C^-1 (K + H)) [s] (a lower bound)."""
        return self._heat_or_error().critical_time_step()

    def add_contact_dampers(self, global_node_indices, tensors, targets, springs=None) -> None:
        """Not collective: add contact dashpots acting in the next step/advance (then cleared).

        The dashpot force on node k is g_k - D_k v_k with D_k (n, 6) symmetric (xx, yy, zz, yz, xz, xy)
        [N s/m] and g_k (n, 3) [N]; it is integrated implicitly at every FE sub-step
        (kernels.apply_contact_dampers).  World components; a solid with motion turns D and g into its
        frame (the velocity they act on is then the elastic velocity relative to the frame).  springs (n, 6):
        symmetric S_k of a contact spring on the node's displacement since the start of the advance, over its
        sub-steps (coupling/dampers.py; world components, for solids without motion)."""
        indices = np.asarray(global_node_indices, dtype=PETSc.IntType).ravel()
        if len(indices) and self.frame is not None:
            tensors = self.frame.symmetric_to_body(np.asarray(tensors, float).reshape(-1, 6), self.time)
            targets = self.frame.vectors_to_body(np.asarray(targets, float).reshape(-1, 3), self.time)
        if len(indices):
            springs = np.zeros((len(indices), 6)) if springs is None else np.asarray(springs, float).reshape(-1, 6)
            values = np.hstack([np.asarray(tensors, float).reshape(-1, 6), np.asarray(targets, float).reshape(-1, 3),
                                springs])
            self.damper_vec.setValuesBlocked(indices, values.ravel(), PETSc.InsertMode.ADD_VALUES)

    def _gather_dampers(self) -> None:
        """Collective: route the dashpots added since the last advance to the owners; keep the damped nodes."""
        self.damper_vec.assemble()
        values = self.damper_vec.getArray().reshape(-1, DAMPER_COLUMNS)  # a local view: no communication
        damped = np.flatnonzero(np.any(values != 0.0, axis=1))
        self._damped_nodes = damped.astype(np.int64)
        self._dampers = np.ascontiguousarray(values[damped])
        values[damped] = 0.0

    def _gather_loads(self) -> None:
        """Collective: load = constant + thermal + the nodal forces added since the last step (routed to owners)."""
        self.nodal_force_vec.assemble()
        self.load_vec.waxpy(1.0, self._base_load_vec, self.nodal_force_vec)

    def _update_base_load(self) -> None:
        self._base_load_vec.waxpy(1.0, self.constant_load_vec, self.thermal_load_vec)

    # ------------------------------------------------------------ constraints
    def prescribe_owned_nodes(self, owned_nodes, displacement=None, velocity=None) -> None:
        """Not collective: constrain owned nodes (numbers 0..n_owned-1) to displacement (n,3) or velocity (n,3).

        For per-node data the scene cannot express (patch tests, coupling); call before static_solve.
        """
        nodes = np.asarray(owned_nodes, dtype=np.int64)
        dofs = (3 * nodes[:, None] + np.arange(3)).ravel()
        self._constrained[dofs] = True
        self._prescribed_displacement[dofs] = 0.0 if displacement is None else np.asarray(displacement, float).ravel()
        self._prescribed_velocity[dofs] = 0.0 if velocity is None else np.asarray(velocity, float).ravel()
        self._static_solver = None
        self._mass_solver = None
        self._set_velocity_from_constraints()

    def _set_velocity_from_constraints(self) -> None:
        v = self.velocity_vec.getArray()
        v[self._constrained] = self._prescribed_velocity[self._constrained]
        self.velocity_vec.setArray(v)

    def _constrained_rows(self) -> np.ndarray:
        return (self.velocity_vec.getOwnershipRange()[0] + np.flatnonzero(self._constrained)).astype(PETSc.IntType)

    # ------------------------------------------------------------------ static
    def static_solve(self) -> StaticResult:
        """Collective: u = K^-1 b with the prescribed displacements; the solid then starts at rest (prescribed velocities aside)."""
        where = f"solid '{self.name}': static solve"
        if _sum(self.comm, float(self._constrained.sum())) == 0:
            raise SolverError(
                where=where, problem="no node is fixed or prescribed: the static problem is singular (rigid-body motion)",
                fix="add a fixed: [...] or prescribed: [...] group, or start without a static solve",
            )
        if self._static_solver is None:
            # GAMG in PETSc 3.18 cannot build its graph from BAIJ: the static copy is AIJ (block size 3 kept).
            constrained = self.stiffness.convert(PETSc.Mat.Type.AIJ, out=PETSc.Mat())  # out=: a copy, not in place
            constrained.zeroRowsColumns(self._constrained_rows(), 1.0)
            self._static_solver = make_static_solver(constrained, self.coordinates_vec)
        self._gather_loads()
        if self.frame is not None:
            self._compute_frame_load()
            self.load_vec.axpy(1.0, self._frame_load_vec)
        prescribed = self.velocity_vec.duplicate()
        prescribed.setArray(np.where(self._constrained, self._prescribed_displacement, 0.0))
        rhs = self.load_vec.duplicate()
        self.stiffness.mult(prescribed, rhs)
        rhs.aypx(-1.0, self.load_vec)  # b - K u_p: the prescribed values' effect on the free rows
        rhs_array = rhs.getArray()
        rhs_array[self._constrained] = self._prescribed_displacement[self._constrained]
        rhs.setArray(rhs_array)
        solution = self.velocity_vec.duplicate()
        result = solve_static(self._static_solver, rhs, solution, where)
        values = solution.getArray()
        values[self._constrained] = self._prescribed_displacement[self._constrained]  # exact, not to solver tolerance
        self.displacement_vec.setArray(values)
        self._divergence_threshold = max(self._diameter, 1e3 * self.displacement_vec.norm(PETSc.NormType.INFINITY))
        self.nodal_force_vec.zeroEntries()
        self.velocity_vec.zeroEntries()
        self._set_velocity_from_constraints()
        self.acceleration_vec.zeroEntries()
        self.stiffness.mult(self.displacement_vec, self.internal_force_vec)
        if self.comm.rank == 0:
            logger.info("solid %s: static solve %s+%s, %d iterations, residual %.3e (rhs %.3e), %s",
                        self.name, result.ksp_type, result.pc_type, result.iterations, result.residual_norm, result.rhs_norm, result.reason)
        return result

    # ---------------------------------------------------------------- explicit
    def largest_frequency_bound(self) -> float:
        """Collective: omega_max bound [rad/s] = sqrt(max element eigenvalue) (see stability.py)."""
        if self._omega_bound is None:
            local = largest_element_eigenvalue(self.mesh.points, self.mesh.cells, self.mesh.n_owned_cells, self.element,
                                               self.lam, self.mu, self.density, self.lumped)
            buffer = np.array([local])
            self.comm.Allreduce(MPI.IN_PLACE, buffer, op=MPI.MAX)
            self._omega_bound = math.sqrt(buffer[0])
        return self._omega_bound

    def critical_time_step(self) -> float:
        """Collective: largest stable central-difference step [s], never above the true one."""
        if self._critical_step is None:
            self._critical_step = critical_step(self.largest_frequency_bound(), self.damping_alpha, self.damping_beta)
        return self._critical_step

    def step(self, dt: float, check_stability: bool = True) -> None:
        """Collective: one central-difference step with this step's nodal forces, which are then cleared.

        A dt above critical_time_step() is refused (SolverError); check_stability=False skips that
        check (the divergence monitor still stops a run that blows up).
        """
        if check_stability:
            self._check_step(dt)
        self.nodal_force_vec.assemble()  # collective: routes every rank's additions to the owners
        self._gather_dampers()
        self._advance(dt, clear_nodal=True)
        self._damped_nodes = self._damped_nodes[:0]
        self._advance_heat(dt)

    def substeps(self, interval: float) -> int:
        """Collective: the fewest equal stable steps that cover `interval` (what `advance` takes)."""
        return max(1, math.ceil(interval / self.critical_time_step() * (1.0 - 1e-12)))

    def advance(self, interval: float) -> int:
        """Collective: cover `interval` with the fewest equal stable steps (sub-cycling); returns their number.

        Nodal forces added before the call act, constant, over the whole interval (impulse-preserving).
        """
        substeps = self.substeps(interval)
        dt = interval / substeps
        self.nodal_force_vec.assemble()
        self._gather_dampers()
        # With one sub-step the springs' displacement since the start is zero: nothing to do.
        self.springs_integrated = substeps > 1
        if self.springs_integrated:
            self._start_springs()
        for substep in range(substeps):
            self._advance(dt, clear_nodal=substep == substeps - 1)
        if self.springs_integrated:
            self._finish_springs()
        self._damped_nodes = self._damped_nodes[:0]
        self._advance_heat(interval)
        return substeps

    def _start_springs(self) -> None:
        """The contact springs of this advance: their rows among the damped nodes and their start displacements."""
        self._spring_rows = np.flatnonzero(np.any(self._dampers[:, 9:15] != 0.0, axis=1))
        nodes = self._damped_nodes[self._spring_rows]
        self._spring_start = self.displacement_vec.getArray(readonly=True).reshape(-1, 3)[nodes].copy()
        self._spring_integral = np.zeros_like(self._spring_start)

    def _finish_springs(self) -> None:
        """The time integral of each spring node's displacement since the start into spring_integral_vec."""
        integral = self.spring_integral_vec.getArray().reshape(-1, 3)
        integral[:] = 0.0
        integral[self._damped_nodes[self._spring_rows]] = self._spring_integral
        self._spring_rows = self._spring_rows[:0]

    def _advance_heat(self, interval: float) -> None:
        """Collective: temperatures over the interval just covered, then the thermal load they give (the
        mechanics of the next advance sees it: a staggered, one-advance-lagged thermo-elastic coupling)."""
        if self.heat is None:
            return
        self.heat.advance(interval)
        # Refreshed after every advance (deciding whether any temperature changed would take a reduction
        # over the ranks per advance; with heat flowing it nearly always has).
        if self._thermal_load_coefficient != 0.0:
            # The strain energy 1/2 u.K u - f_th.u + E_th jumps at fixed u when the thermal load changes:
            # book it, so an energy balance of the solid can close.
            before = self._thermal_energy - self.thermal_load_vec.dot(self.displacement_vec)
            self._refresh_thermal_load()
            self.thermoelastic_work += self._thermal_energy - self.thermal_load_vec.dot(self.displacement_vec) - before

    def _check_step(self, dt: float) -> None:
        limit = self.critical_time_step()
        if dt > limit * (1.0 + 1e-12):
            raise SolverError(
                where=f"solid '{self.name}': time step",
                problem=(
                    f"dt = {dt:.4e} s exceeds the critical central-difference step {limit:.4e} s "
                    f"(omega_max <= {self.largest_frequency_bound():.4e} rad/s from the element bound)"
                ),
                fix="lower time.dt, refine less, or let the coupling sub-cycle the solid (Solid.advance)",
            )

    def _compute_frame_load(self) -> None:
        """The frame's loads at the current time and displacement (frame.frame_load) into _frame_load_vec."""
        frame = self.frame
        # Gravity and, with a free axis, the frame's acceleration (-m a, like a body force) in the frame's axes.
        effective = np.asarray(self.gravity, float) - frame.acceleration
        body_gravity = frame.vectors_to_body(effective[None, :], self.time)[0]
        spinning = frame.moving(self.time)
        frame_load(self.displacement_vec.getArray(readonly=True), self._lumped_mass_values,
                   self._centrifugal_reference if spinning else self._no_centrifugal_load, self._gravity_unit_loads,
                   body_gravity, frame.spin_vector(self.time), self._frame_load_vec.getArray())

    def _advance(self, dt: float, clear_nodal: bool) -> None:
        base_load = self._base_load_vec
        springs = len(self._spring_rows) > 0
        if springs:
            # The contact springs' forces at this sub-step's displacement join the held nodal loads for the step.
            spring_forces = kernels.contact_spring_forces(
                self.displacement_vec.getArray(readonly=True), self._damped_nodes, self._dampers, self._spring_rows,
                self._spring_start, self._spring_integral, dt, self.nodal_force_vec.getArray())
        if self.frame is not None:
            velocity_before = self.velocity_vec.getArray(readonly=True).copy()
            self._compute_frame_load()
            self._frame_base_vec.waxpy(1.0, self._base_load_vec, self._frame_load_vec)
            base_load = self._frame_base_vec
        if self.damping_beta != 0.0:
            # beta K v- apart from K u: the damping's work is booked with it (a second product, only with beta).
            self.stiffness.mult(self.velocity_vec, self._stiffness_damping_vec)
            self._stiffness_damping_vec.scale(self.damping_beta)
            self.stiffness.mult(self.displacement_vec, self.internal_force_vec)
            self.internal_force_vec.axpy(1.0, self._stiffness_damping_vec)
            stiffness_damping_force = self._stiffness_damping_vec.getArray(readonly=True)
        else:
            self.stiffness.mult(self.displacement_vec, self.internal_force_vec)
            stiffness_damping_force = _NO_DAMPING_FORCE
        consistent_mass_damping = not self.lumped and self.damping_alpha != 0.0
        if consistent_mass_damping:
            velocity_before_step = self.velocity_vec.getArray(readonly=True).copy()
        if not self.lumped:
            self.load_vec.waxpy(1.0, self._base_load_vec, self.nodal_force_vec)
            self._solve_consistent_mass()
        half_alpha = 0.5 * self.damping_alpha * dt
        decay, gain = (1.0 - half_alpha) / (1.0 + half_alpha), 1.0 / (1.0 + half_alpha)
        # getArray() views: petsc4py restores (and bumps the state of) each Vec before the kernel writes
        # in place, and nothing reads a cached norm in between, so no copies are needed.
        work, support_work, self._support_half_step, damping_work = kernels.central_difference_update(
            self.displacement_vec.getArray(), self.velocity_vec.getArray(), self.acceleration_vec.getArray(),
            self.internal_force_vec.getArray(readonly=True), base_load.getArray(readonly=True),
            self.nodal_force_vec.getArray(), self.load_vec.getArray(), self._inverse_lumped_mass, self._constrained,
            self._prescribed_velocity, dt, decay, gain, self.lumped, clear_nodal,
            self.damping_alpha if self.lumped else 0.0, self._lumped_mass_values, stiffness_damping_force,
        )
        if consistent_mass_damping:
            damping_work += self._consistent_mass_damping_work(velocity_before_step, dt)
        self._damping_work_local += damping_work
        if len(self._damped_nodes):
            self.damper_work_local += kernels.apply_contact_dampers(
                self.displacement_vec.getArray(), self.velocity_vec.getArray(), self.acceleration_vec.getArray(),
                self._lumped_mass_values, self._constrained, self._damped_nodes, self._dampers, dt, decay, gain)
        if self.frame is not None:
            velocities = self.velocity_vec.getArray()
            coriolis_correction(self.displacement_vec.getArray(), velocities, velocity_before, self._constrained,
                                self.frame.spin_vector(self.time), dt)
            self.frame_work_local += load_work(self._frame_load_vec.getArray(readonly=True), velocity_before,
                                               self.velocity_vec.getArray(readonly=True), self._constrained, dt)
        if springs and not clear_nodal:
            kernels.remove_nodal_forces(self._damped_nodes[self._spring_rows], spring_forces,
                                        self.nodal_force_vec.getArray())
        self._external_work_local += work
        self._support_work_local += support_work
        self.time += dt
        self.step_count += 1
        if self.step_count % BLOWUP_CHECK_EVERY == 0:
            self._check_divergence(dt)

    def _consistent_mass_damping_work(self, velocity_before_step: np.ndarray, dt: float) -> float:
        """This rank's share of the step's work of alpha M v-bar with the consistent M, on the free dofs'
        increment dt v-bar (v-bar = (v- + v+) / 2, zero at constrained dofs, whose rows the mass solve holds)."""
        values = 0.5 * (velocity_before_step + self.velocity_vec.getArray(readonly=True))
        values[self._constrained] = 0.0
        self._work_vec.setArray(values)  # (the mass solve's residual: free again after the step)
        self.consistent_mass.mult(self._work_vec, self._stiffness_damping_vec)
        return self.damping_alpha * dt * float(np.dot(values, self._stiffness_damping_vec.getArray(readonly=True)))

    def _solve_consistent_mass(self) -> None:
        if self._mass_solver is None:
            constrained = self.consistent_mass.duplicate(copy=True)
            constrained.zeroRowsColumns(self._constrained_rows(), 1.0)
            ksp = PETSc.KSP().create(comm=self.comm)
            ksp.setOptionsPrefix(MASS_SOLVE_PREFIX)
            ksp.setOperators(constrained)
            ksp.setType(PETSc.KSP.Type.CG)
            ksp.getPC().setType(PETSc.PC.Type.JACOBI)
            ksp.setTolerances(rtol=MASS_SOLVE_RTOL, atol=1e-300, max_it=500)
            ksp.setInitialGuessNonzero(True)  # last step's acceleration: a few iterations
            ksp.setFromOptions()
            self._mass_solver = ksp
        residual = self._work_vec
        residual.waxpy(-1.0, self.internal_force_vec, self.load_vec)
        r = residual.getArray()
        r[self._constrained] = 0.0
        residual.setArray(r)
        self._mass_solver.solve(residual, self.acceleration_vec)
        if self._mass_solver.getConvergedReason() < 0:
            raise SolverError(where=f"solid '{self.name}': consistent mass solve",
                              problem=f"CG+Jacobi failed ({self._mass_solver.getConvergedReason()})",
                              fix="use mass: lumped, or pass -fem_mass_ksp_max_it / -fem_mass_ksp_rtol")

    def _check_divergence(self, dt: float) -> None:
        largest = self.displacement_vec.norm(PETSc.NormType.INFINITY)
        if not np.isfinite(largest) or largest > self._divergence_threshold:
            raise SolverError(
                where=f"solid '{self.name}': explicit step {self.step_count} (t = {self.time:.4e} s)",
                problem=(
                    f"the solution blew up: max |u| = {largest:.3e} m exceeds {self._divergence_threshold:.3e} m "
                    f"(the solid's size, or 1000 x the displacement of the last static solve) "
                    f"(dt = {dt:.4e} s, critical step bound {self.critical_time_step():.4e} s)"
                ),
                fix="lower the time step (dt above the critical step grows the highest mode every step)",
            )

    # ----------------------------------------------------------------- state
    @property
    def external_work(self) -> float:
        """Collective: work of the applied loads and supports since construction [J], summed over the ranks."""
        self._external_work_summed += _sum(self.comm, self._external_work_local)
        self._external_work_local = 0.0
        return self._external_work_summed

    @external_work.setter
    def external_work(self, value: float) -> None:
        self._external_work_summed = float(value)
        self._external_work_local = 0.0

    @property
    def support_work(self) -> float:
        """Collective: work [J] the fixed and prescribed groups' reactions did since construction, summed over the
        ranks: zero for groups held still (fixed, a constant prescribed displacement), the energy a prescribed
        velocity feeds in."""
        booked, half_step = self._settle_support_work()
        return booked + half_step

    def _settle_support_work(self) -> tuple:
        """Collective: (the supports' work booked up to the last step's middle, the half step after it)."""
        summed = np.array([self._support_work_local, self._support_half_step])
        self.comm.Allreduce(MPI.IN_PLACE, summed, op=MPI.SUM)
        self._support_work_summed += float(summed[0])
        self._support_work_local = 0.0
        return self._support_work_summed, float(summed[1])

    @property
    def damping_work(self) -> float:
        """Collective: energy [J] the Rayleigh damping (alpha M + beta K) took from the elastic motion since
        construction, summed over the ranks (0 without damping)."""
        self._damping_work_summed += _sum(self.comm, self._damping_work_local)
        self._damping_work_local = 0.0
        return self._damping_work_summed

    @property
    def frame_work(self) -> float:
        """Collective: work [J] the moving frame's loads (centrifugal, gravity turned into the frame) did on the
        elastic motion since construction, summed over the ranks (0 without motion)."""
        if self.frame is None:
            return 0.0
        self._frame_work_summed += _sum(self.comm, self.frame_work_local)
        self.frame_work_local = 0.0
        return self._frame_work_summed

    @property
    def positions(self) -> np.ndarray:
        """Current positions (n_owned, 3) [m] (world; with motion, the frame carries X + u)."""
        body = self.mesh.points[: self.n_owned_nodes] + self.displacements
        return body if self.frame is None else self.frame.to_world(body, self.time)

    @property
    def world_displacements(self) -> np.ndarray:
        """positions - reference positions (n_owned, 3) [m]: the displacement a viewer sees (with motion it
        holds the rigid motion too; `displacements` is the elastic part, in the frame's axes)."""
        if self.frame is None:
            return self.displacements  # exactly u (positions - X would round)
        return self.positions - self.mesh.points[: self.n_owned_nodes]

    @property
    def world_velocities(self) -> np.ndarray:
        """Velocities in world axes (n_owned, 3) [m/s]: with motion V + omega x R (X + u - c0) + R u'."""
        if self.frame is None:
            return self.velocities
        body = self.mesh.points[: self.n_owned_nodes] + self.displacements
        return self.frame.world_velocities(body, self.velocities, self.time)

    @property
    def reference_positions(self) -> np.ndarray:
        return self.mesh.points[: self.n_owned_nodes].copy()

    @property
    def displacements(self) -> np.ndarray:
        return self.displacement_vec.getArray(readonly=True).reshape(-1, 3).copy()

    @property
    def velocities(self) -> np.ndarray:
        """Velocity over the last step v^{n-1/2} (exact for prescribed nodes), (n_owned, 3) [m/s]; with
        motion the elastic velocity relative to the frame, in its axes (world_velocities: the total)."""
        return self.velocity_vec.getArray(readonly=True).reshape(-1, 3).copy()

    @property
    def temperatures(self) -> np.ndarray:
        return self.temperature_vec.getArray(readonly=True).copy()

    @property
    def original_node_ids(self) -> np.ndarray:
        """Owned nodes' numbers in the input mesh (P2 midside nodes: n_corners + edge number)."""
        return self.mesh.original_node_ids

    @property
    def original_cell_ids(self) -> np.ndarray:
        return self.mesh.original_cell_ids

    @property
    def constrained_dofs(self) -> np.ndarray:
        """Owned dofs (3 per node, x y z) held by fixed or prescribed groups, as a boolean mask (copy)."""
        return self._constrained.copy()

    # ----------------------------------------------------------- checkpoints
    def _checkpointed_vectors(self) -> dict:
        return {"u": self.displacement_vec, "v": self.velocity_vec, "a": self.acceleration_vec,
                "internal": self.internal_force_vec, "load": self.load_vec}

    def state_dict(self) -> dict:
        """Collective: the FE vectors by input node number (rank-count independent slabs) and the clock."""
        nodes = np.asarray(self.original_node_ids, dtype=np.int64)
        state = {key: kinds.keyed_slab(vec.getArray(readonly=True).reshape(-1, 3).copy(), nodes)
                 for key, vec in self._checkpointed_vectors().items()}
        state["T"] = kinds.keyed_slab(self.temperature_vec.getArray(readonly=True).copy(), nodes)
        state["time"] = kinds.scalar(float(self.time))
        state["step_count"] = kinds.scalar(int(self.step_count))
        state["external_work"] = kinds.scalar(float(self.external_work))
        booked, half_step = self._settle_support_work()
        state["support_work"] = kinds.scalar(booked)
        state["support_half_step"] = kinds.scalar(half_step)
        state["damping_work"] = kinds.scalar(float(self.damping_work))
        if self.frame is not None:
            state["frame_work"] = kinds.scalar(float(self.frame_work))
            state["frame"] = {key: kinds.scalar(float(value)) for key, value in self.frame.state().items()}
        if self.heat is not None:
            state["heat"] = self.heat.state_dict(nodes)
            state["heat"]["thermoelastic_work"] = kinds.scalar(float(self.thermoelastic_work))
        return state

    def load_state_dict(self, state: dict) -> None:
        """Collective: this rank's nodes' rows of the stored vectors (read whole, by input node number)."""
        stored = len(state["u"])
        if stored != self.n_global_nodes:
            raise kinds.StateMismatch(f"solid '{self.name}' has {stored} nodes in the checkpoint, "
                                      f"{self.n_global_nodes} in this scene's mesh")
        nodes = np.asarray(self.original_node_ids, dtype=np.int64)
        for key, vec in self._checkpointed_vectors().items():
            vec.setArray(np.ascontiguousarray(np.asarray(state[key])[nodes]).ravel())
        temperatures = np.asarray(state["T"])[nodes]
        if not np.array_equal(temperatures, self.temperatures):
            self.set_temperature(temperatures)
        self.displacement_vec.ghostUpdate(addv=PETSc.InsertMode.INSERT_VALUES, mode=PETSc.ScatterMode.FORWARD)
        self.time, self.step_count = float(state["time"]), int(state["step_count"])
        self.external_work = float(state["external_work"])
        # The last step's half, held by rank 0 alone: the sum over the ranks reads it back unchanged.
        self._support_half_step = float(state["support_half_step"]) if self.comm.rank == 0 else 0.0
        self._support_work_summed, self._support_work_local = float(state["support_work"]), 0.0
        self._damping_work_summed, self._damping_work_local = float(state["damping_work"]), 0.0
        if (self.frame is None) != ("frame_work" not in state):
            here, there = ("has no", "has") if self.frame is None else ("has", "has no")
            raise kinds.StateMismatch(f"solid '{self.name}' {here} motion: in this scene, it {there} in the checkpoint")
        if self.frame is not None:
            self._frame_work_summed, self.frame_work_local = float(state["frame_work"]), 0.0
            self.frame.load_state(state["frame"])
        if (self.heat is None) != ("heat" not in state):
            here, there = ("does not", "does") if self.heat is None else ("does", "does not")
            raise kinds.StateMismatch(f"solid '{self.name}' {here} conduct heat in this scene, it {there} in the checkpoint")
        if self.heat is not None:
            self.heat.load_state_dict(state["heat"], nodes)
            self.thermoelastic_work = float(state["heat"]["thermoelastic_work"])
        # The dashpot work since the checkpoint (the coupling keeps the total up to it).
        self.damper_work_local = 0.0

    def set_state(self, displacements, velocities) -> None:
        """Not collective: owned displacements and half-step velocities (n_owned, 3), e.g. from a checkpoint."""
        self.displacement_vec.setArray(np.asarray(displacements, float).ravel())
        self.velocity_vec.setArray(np.asarray(velocities, float).ravel())

    # -------------------------------------------------------- post-processing
    @property
    def stresses(self) -> np.ndarray:
        """Collective: Cauchy stress at each owned cell's centroid, Voigt (xx, yy, zz, yz, xz, xy) [Pa], in world
        axes (a solid with motion computes it in its frame and turns it)."""
        displacement = local_values(self.displacement_vec, 3)
        delta_t = local_values(self.temperature_vec, 1)[:, 0] - self.reference_temperature
        out = np.empty((self.mesh.n_owned_cells, 6))
        kernels.cell_stresses(self.mesh.points, self.mesh.cells, self.mesh.n_owned_cells, displacement, delta_t,
                              self.element.centroid_gradients, self.element.centroid_values, self.lam, self.mu,
                              self._thermal_load_coefficient, out)
        return out if self.frame is None else self.frame.symmetric_to_world(out, self.time)

    @property
    def von_mises(self) -> np.ndarray:
        """Collective: von Mises stress per owned cell (at the centroid) [Pa]."""
        s = self.stresses
        return np.sqrt(0.5 * ((s[:, 0] - s[:, 1]) ** 2 + (s[:, 1] - s[:, 2]) ** 2 + (s[:, 2] - s[:, 0]) ** 2)
                       + 3.0 * (s[:, 3] ** 2 + s[:, 4] ** 2 + s[:, 5] ** 2))

    def group_node_numbers(self, group: str) -> np.ndarray:
        """Owned node numbers (0..n_owned-1) on a fixed/prescribed/traction/contact group."""
        if group not in self.mesh.group_nodes:
            raise MeshError(where=f"{self.mesh.source}: group '{group}'",
                            problem=f"solid '{self.name}' does not use this group (known: {sorted(self.mesh.group_nodes)})",
                            fix="name it under fixed, prescribed, tractions or contact")
        return self.mesh.group_nodes[group]

    def reaction(self, group: str) -> np.ndarray:
        """Collective: total force (3,) [N] the supports exert on the group's nodes at the last force evaluation.

        R = K (u + beta v) + C_alpha v + M a - f on the group's nodes (after a static solve: K u - f),
        summed over ranks; meaningful on fixed and prescribed groups.
        """
        nodes = self.group_node_numbers(group)
        force = (self.internal_force_vec.getArray(readonly=True) - self.load_vec.getArray(readonly=True)).reshape(-1, 3)
        if self.lumped:
            mass = self.lumped_mass.getArray(readonly=True)
            inertia = mass * (self.acceleration_vec.getArray(readonly=True) + self.damping_alpha * self.velocity_vec.getArray(readonly=True))
        else:
            product = self.velocity_vec.duplicate()
            self._work_vec.waxpy(self.damping_alpha, self.velocity_vec, self.acceleration_vec)
            self.consistent_mass.mult(self._work_vec, product)
            inertia = product.getArray(readonly=True)
        total = (force + inertia.reshape(-1, 3))[nodes].sum(axis=0)
        self.comm.Allreduce(MPI.IN_PLACE, total, op=MPI.SUM)
        # With motion: the elastic (frame) part of the support force, turned into world axes; the frame's own
        # inertial loads are among the applied loads, so this is what the supports add to them.
        return total if self.frame is None else self.frame.vectors_to_world(total[None, :], self.time)[0]

    def kinetic_energy(self) -> float:
        """Collective: 1/2 v^T M v with the half-step velocity [J]."""
        if self.lumped:
            v = self.velocity_vec.getArray(readonly=True)
            return 0.5 * _sum(self.comm, float(np.dot(v * self.lumped_mass.getArray(readonly=True), v)))
        product = self.velocity_vec.duplicate()
        self.consistent_mass.mult(self.velocity_vec, product)
        return 0.5 * product.dot(self.velocity_vec)

    def strain_energy(self) -> float:
        """Collective: int 1/2 (eps - eps_th) : D : (eps - eps_th) dV [J] (exact quadrature)."""
        product = self.velocity_vec.duplicate()
        self.stiffness.mult(self.displacement_vec, product)
        return 0.5 * product.dot(self.displacement_vec) - self.thermal_load_vec.dot(self.displacement_vec) + self._thermal_energy

    def smallest_volume_ratio(self) -> tuple:
        """Collective: (smallest deformed / undeformed volume of a cell's corner tetrahedron, cells at or below zero),
        over all ranks.  A cell turned inside out is beyond what the small-strain model describes; its faces no
        longer bound the solid, so particles can pass through (the run monitor stops there)."""
        corners = self.mesh.cells[:self.mesh.n_owned_cells, :4]
        if self._corner_volumes is None:
            self._corner_volumes = _corner_volumes(self.mesh.points, corners)
        ratios = _corner_volumes(self.mesh.points + local_values(self.displacement_vec, 3), corners) / self._corner_volumes
        local = np.array([ratios.min() if len(ratios) else np.inf, -float(np.count_nonzero(ratios <= 0.0))])
        if self.comm.size > 1:
            self.comm.Allreduce(MPI.IN_PLACE, local, op=MPI.MIN)  # the count's negative: MIN gives the largest
        return float(local[0]), int(-local[1])

    # ---------------------------------------------------------------- surface
    def contact_surface(self, groups=None) -> ContactSurface:
        """Collective on first use: the contact groups' triangles and a gather of their nodes' state."""
        groups = tuple(self.config.contact if groups is None else groups)
        unknown = [g for g in groups if g not in self.mesh.contact_faces]
        if unknown:
            raise MeshError(where=f"{self.mesh.source}: group '{unknown[0]}'",
                            problem=f"not a contact group of solid '{self.name}' (contact: {list(self.config.contact)})",
                            fix="list it under the solid's contact: key")
        if groups not in self._surfaces:
            self._surfaces[groups] = ContactSurface(self.mesh.contact_faces, groups, self.coordinates_vec,
                                                    self.mesh.contact_faces_input)
        return self._surfaces[groups]

    def surface_triangles(self, groups=None) -> np.ndarray:
        """Collective on first use: (nt, 3) global node numbers of the contact triangles, outward-oriented, same on every rank."""
        return self.contact_surface(groups).triangles_global

    def surface_state(self, groups=None) -> tuple:
        """Collective: (node numbers (ns,), positions (ns,3), velocities (ns,3)) of the contact nodes on every rank
        (world: with motion the frame carries them)."""
        surface = self.contact_surface(groups)
        positions, velocities = surface.gather(self.displacement_vec, self.velocity_vec)
        if self.frame is not None:
            return surface.node_indices, *self.frame_to_world(positions, velocities)
        return surface.node_indices, positions, velocities

    def frame_to_world(self, body_positions, body_velocities) -> tuple:
        """(positions, velocities) in world axes of points of this solid given in its frame (X + u, u'), now."""
        if self.frame is None:
            return body_positions, body_velocities
        return (self.frame.to_world(body_positions, self.time),
                self.frame.world_velocities(body_positions, body_velocities, self.time))


def _corner_volumes(points: np.ndarray, corners: np.ndarray) -> np.ndarray:
    """Six times the signed volume of each cell's corner tetrahedron."""
    a = points[corners[:, 0]]
    return np.einsum("ij,ij->i", np.cross(points[corners[:, 1]] - a, points[corners[:, 2]] - a), points[corners[:, 3]] - a)

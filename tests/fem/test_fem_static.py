"""Static verification: patch test, cantilever convergence and P1 locking, reactions, thermal bars."""
import numpy as np
import pytest

from fem_helpers import box_solid, direct_solver, material, unstructured_box_msh
from pdemfem.errors import SolverError
from pdemfem.fem import Solid, SolidConfig

# LU on these small, well-conditioned systems (~10^3 unknowns, kappa(K) ~ 1e3): relative error ~ kappa eps in
# the displacements; stresses are differences of nodal values over cells of size h ~ |x| / 10, so 10x that.
LU_ROUND_OFF = 1e3 * np.finfo(float).eps       # 2.2e-13
STRESS_ROUND_OFF = 10 * LU_ROUND_OFF           # 2.2e-12

# A uniform strain (symmetric part) with a rotation (antisymmetric part) and a translation.
GRADIENT = np.array([[1.0e-3, 4.0e-4, -2.0e-4], [1.0e-4, -5.0e-4, 3.0e-4], [6.0e-4, -1.0e-4, 2.0e-4]])
SHIFT = np.array([1e-4, -2e-4, 3e-4])


@pytest.mark.parametrize("element", ["P1", "P2"])
def test_patch_test_reproduces_uniform_strain_exactly(tmp_path, element):
    path = unstructured_box_msh(tmp_path / "patch.msh", size=0.25)
    config = SolidConfig(name="patch", mesh=path, material="m", element=element, contact=["boundary"])
    mat = material(E=1.0, nu=0.3)
    solid = Solid(config, mat, gravity=(0, 0, 0))
    boundary = solid.group_node_numbers("boundary")
    exact = solid.reference_positions @ GRADIENT.T + SHIFT
    solid.prescribe_owned_nodes(boundary, displacement=exact[boundary])
    with direct_solver():
        solid.static_solve()
    interior = np.setdiff1d(np.arange(solid.n_owned_nodes), boundary)
    assert len(interior) > 5  # the patch has free nodes to get wrong
    # round-off only (measured 3.6e-16 P1, 3.7e-15 P2)
    assert np.abs(solid.displacements - exact).max() <= LU_ROUND_OFF * np.abs(exact).max()
    strain = 0.5 * (GRADIENT + GRADIENT.T)
    lam, mu = solid.lam, solid.mu
    sigma = lam * np.trace(strain) * np.eye(3) + 2 * mu * strain
    voigt = np.array([sigma[0, 0], sigma[1, 1], sigma[2, 2], sigma[1, 2], sigma[0, 2], sigma[0, 1]])
    # every cell carries the same stress, to round-off of the gradients (measured 2.9e-15 P1, 1.3e-14 P2)
    assert np.abs(solid.stresses - voigt).max() <= STRESS_ROUND_OFF * np.abs(voigt).max()


def _cantilever_compliance(element, cells, nu=0.0):
    """Tip deflection work-conjugate to a uniform shear traction (exact FE compliance) and beam theory."""
    E, L, P = 1000.0, 10.0, 1.0
    solid = box_solid((0, 0, 0), (L, 1, 1), cells, material(E=E, nu=nu), element=element, fixed=["xmin"],
                      tractions=[{"group": "xmax", "traction": [0.0, 0.0, -P]}])
    solid.static_solve()
    deflection = solid.load_vec.dot(solid.displacement_vec) / P
    I, A, G = 1.0 / 12.0, 1.0, E / (2 * (1 + nu))
    kappa = 10 * (1 + nu) / (12 + 11 * nu)  # Cowper's shear coefficient, rectangle
    timoshenko = P * L**3 / (3 * E * I) + P * L / (kappa * G * A)
    return deflection / timoshenko


def test_cantilever_p2_converges_to_beam_solution():
    # nu = 0: no Poisson constraint at the clamped root, so Timoshenko's beam with kappa = 5/6 is the
    # 3-D limit (measured: P2 on 40x4x4 gives 1.00000).  Compliance of a conforming FE is a lower bound.
    coarse = _cantilever_compliance("P2", (5, 1, 1))
    modest = _cantilever_compliance("P2", (10, 1, 1))
    assert coarse < modest < 1.0 + 1e-9  # monotone, from below (energy bound; 1e-9 for solver tolerance)
    assert 1.0 - modest < 0.01  # the 1 % on a modest mesh (10x1x1 hexahedra, 567 dofs); measured 0.19 %
    assert (1.0 - coarse) / (1.0 - modest) > 3.0  # h^2 convergence would give 4; measured 3.9


def test_p1_locking_is_measured():
    # Linear tetrahedra cannot bend without spurious shear strain: the beam is far too stiff on
    # coarse meshes and recovers only slowly (measured ratios 0.198, 0.463 versus P2's 0.998).
    ratios = [_cantilever_compliance("P1", cells) for cells in ((10, 1, 1), (20, 2, 2))]
    p2_same_mesh = _cantilever_compliance("P2", (10, 1, 1))
    assert ratios[0] < 0.5 * p2_same_mesh  # locking: less than half the deflection on the same mesh
    assert ratios[0] < ratios[1] < 1.0  # converges from below under refinement, but slowly
    assert ratios[1] < 0.9


@pytest.mark.parametrize("element", ["P1", "P2"])
def test_bar_reaction_balances_gravity_and_traction(element):
    mat = material(E=2e11, nu=0.3, rho=7800.0)
    gravity = (0.0, 1.0, -9.81)
    solid = box_solid((0, 0, 0), (2.0, 0.2, 0.3), (6, 2, 2), mat, gravity=gravity, element=element, fixed=["xmin"],
                      tractions=[{"group": "xmax", "traction": [5e4, 0.0, 1e3]}])
    result = solid.static_solve()
    volume, end_area = 2.0 * 0.2 * 0.3, 0.2 * 0.3
    applied = 7800.0 * volume * np.array(gravity) + end_area * np.array([5e4, 0.0, 1e3])
    reaction = solid.reaction("xmin")
    # sum of all rows of K u vanishes (translations are in K's null space), so R + F equals the sum of the
    # free rows' residual: |R + F| <= sqrt(n) ||b - K u|| (plus round-off of K 1 = 0)
    n = 3 * solid.n_global_nodes
    bound = np.sqrt(n) * result.residual_norm + 1e-12 * np.abs(applied).max()
    assert np.all(np.abs(reaction + applied) <= bound)
    assert result.residual_norm <= 1e-10 * result.rhs_norm * 1.0001  # the default -fem_ksp_rtol 1e-10, true residual


def _thermal_bar(element, clamp_both_ends):
    E, alpha, dT = 2e11, 1.2e-5, 100.0
    prescribed = [
        {"group": "xmin", "displacement": [0.0, None, None]},
        {"group": "ymin", "displacement": [None, 0.0, None]},
        {"group": "zmin", "displacement": [None, None, 0.0]},
    ]
    if clamp_both_ends:
        prescribed.append({"group": "xmax", "displacement": [0.0, None, None]})
    solid = box_solid((0, 0, 0), (2.0, 0.5, 0.4), (4, 2, 2), material(E=E, nu=0.3, rho=7800.0, alpha=alpha), element=element,
                      prescribed=prescribed, initial_temperature=293.15 + dT, reference_temperature=293.15)
    with direct_solver():
        solid.static_solve()
    return solid, E * alpha * dT, alpha * dT


@pytest.mark.parametrize("element", ["P1", "P2"])
def test_free_thermal_expansion_is_stress_free(element):
    solid, stress_scale, strain = _thermal_bar(element, clamp_both_ends=False)
    # rollers on three faces: the body expands freely, u = alpha dT x exactly (a linear field); measured
    # 1.7e-14 of the largest displacement (2.4 mm) for P2
    assert np.abs(solid.displacements - strain * solid.reference_positions).max() <= LU_ROUND_OFF * strain * 2.0
    # stress-free to round-off of E alpha dT (2.4e8 Pa; measured 2.4e-14 of it for P2) ...
    assert np.abs(solid.stresses).max() <= STRESS_ROUND_OFF * stress_scale
    # ... and energy-free: the energy is a difference of terms of the clamped bar's size (measured 1.0e-14)
    assert abs(solid.strain_energy()) <= LU_ROUND_OFF * 0.5 * stress_scale * strain * 0.4


@pytest.mark.parametrize("element", ["P1", "P2"])
def test_clamped_thermal_bar_gives_minus_E_alpha_dT(element):
    solid, stress_scale, strain = _thermal_bar(element, clamp_both_ends=True)
    stresses = solid.stresses
    # uniaxial: sigma_xx = -E alpha dT in every cell, the rest zero, to round-off (measured <= 1.3e-14)
    assert np.abs(stresses[:, 0] + stress_scale).max() <= STRESS_ROUND_OFF * stress_scale
    assert np.abs(stresses[:, 1:]).max() <= STRESS_ROUND_OFF * stress_scale
    assert np.allclose(solid.von_mises, stress_scale, rtol=STRESS_ROUND_OFF, atol=0)
    volume = 2.0 * 0.5 * 0.4
    # energy and reaction: sums over the cells / the end face's nodes (measured 5.1e-15, 8.9e-16)
    assert solid.strain_energy() == pytest.approx(0.5 * stress_scale * strain * volume, rel=LU_ROUND_OFF)
    # the end support pushes back with sigma A
    assert solid.reaction("xmax")[0] == pytest.approx(-stress_scale * 0.5 * 0.4, rel=LU_ROUND_OFF)


def test_unsupported_solid_static_solve_is_refused():
    solid = box_solid((0, 0, 0), (1, 1, 1), (1, 1, 1), material(), gravity=(0, 0, -9.81))
    with pytest.raises(SolverError, match="singular"):
        solid.static_solve()


def test_options_prefix_reaches_the_solver():
    solid = box_solid((0, 0, 0), (4, 1, 1), (4, 1, 1), material(), gravity=(0, 0, -1.0), fixed=["xmin"])
    from fem_helpers import petsc_options

    with petsc_options(fem_ksp_max_it=1, fem_ksp_rtol=1e-14):
        with pytest.raises(SolverError, match="DIVERGED_MAX_IT"):
            solid.static_solve()

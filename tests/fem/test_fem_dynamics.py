"""Explicit dynamics: wave speed, bending frequency, energy conservation, critical step and blow-up detection."""
import numpy as np
import pytest

from fem_helpers import box_solid, dense, material
from pdemfem.errors import SolverError


def front_tail_envelope(h: float, courant: float, travelled: float, distances, spacing: float) -> float:
    """Envelope of the probe error of test_longitudinal_wave_travels_at_bar_speed: the dispersion tail of the
    discrete front.  Central difference with lumped mass on a 1-D chain has omega = ck - beta k^3 with
    beta = c h^2 (1 - C^2) / 24 (C the Courant number): the long waves travel at exactly c, the short ones lag,
    and a velocity step spreads into an Airy profile of width w = (c t h^2 (1 - C^2) / 8)^(1/3) whose total
    displacement defect is zero.  At s = d / w widths behind the front the displacement error is
    v0 w / c * int_s^inf of the Airy tail <= v0 w / c * s^(-5/4) / sqrt(pi), so the relative error of
    u1 - u2 = v0 spacing / c is at most (w / spacing) sum_probes s^(-5/4) / sqrt(pi)."""
    width = (travelled * h**2 * (1.0 - courant**2) / 8.0) ** (1.0 / 3.0)
    return width / spacing * sum((d / width) ** -1.25 for d in distances) / np.sqrt(np.pi)


def test_longitudinal_wave_travels_at_bar_speed():
    # 1-D setting: nu = 0 (no lateral coupling), a velocity step v0 at x = 0.  Behind the front
    # u(x, t) = v0 (t - x / c), so two probes give c = v0 (x2 - x1) / (u1 - u2) exactly in the continuum;
    # measured before the reflection from x = L returns to x2 = L/2 (t < 1.5 L / c).
    E, rho, L, v0 = 2e11, 7800.0, 1.0, 1e-3
    c = np.sqrt(E / rho)
    for nx in (40, 80):
        solid = box_solid((0, 0, 0), (L, 0.05, 0.05), (nx, 1, 1), material(E=E, nu=0.0, rho=rho),
                          prescribed=[{"group": "xmin", "velocity": [v0, None, None]}])
        end = 1.4 * L / c
        steps = int(np.ceil(end / solid.critical_time_step()))
        for _ in range(steps):
            solid.step(end / steps)
        x = solid.reference_positions[:, 0]
        u = solid.displacements[:, 0]
        u1, u2 = u[np.isclose(x, 0.25 * L)].mean(), u[np.isclose(x, 0.5 * L)].mean()
        error = abs(v0 * 0.25 * L / (u1 - u2) / c - 1.0)
        # The incident front is at 1.4 L (reflected: 0.6 L, which the probes at 0.25 L, 0.5 L lie ahead of, where
        # the Airy profile decays exponentially): the probes are 1.15 L and 0.9 L behind it.
        envelope = front_tail_envelope(L / nx, c * end / steps / (L / nx), c * end, (1.15 * L, 0.9 * L), 0.25 * L)
        print(f"nx = {nx}: wave speed error {error:.3g}, dispersion-tail envelope {envelope:.3g}")
        # The error is the tail's oscillation at the probes: its sign and size depend on the phase there, so it
        # is not monotone in h (measured 2.7e-4 at nx = 40, 2.4e-4 at 80, 1.1e-4 at 160), within the envelope
        # (3.5e-3, 1.1e-3, 3.6e-4: it falls as h^(3/2)).  The envelope is asymptotic in s: at nx = 20 (s ~ 12)
        # the measured 1.3e-2 exceeds its 1.2e-2, hence nx >= 40.  A stiffness or mass wrong by 0.4 % shifts c
        # itself by 2e-3 and fails nx = 80.
        assert error <= envelope


def modified_energy(solid, dt):
    """(H, midpoint energy, kinetic energy).  H is exactly conserved by undamped, unloaded central difference:
    H = 1/2 v^T (M - dt^2/4 K) v + 1/2 ubar^T K ubar,  ubar = (u^n + u^{n+1}) / 2,  v = v^{n+1/2}."""
    v = solid.velocity_vec
    work = v.duplicate()
    ubar = solid.displacement_vec.copy()
    ubar.axpy(-0.5 * dt, v)
    solid.stiffness.mult(v, work)
    vKv = work.dot(v)
    solid.stiffness.mult(ubar, work)
    kinetic = solid.kinetic_energy()
    midpoint = kinetic + 0.5 * work.dot(ubar)
    return midpoint - dt**2 / 8 * vKv, midpoint, kinetic


@pytest.fixture(scope="module")
def released_cantilever():
    """P2 cantilever (L/h = 10, width 2 so z-bending is the lowest mode) released from its gravity sag.

    Records the tip deflection every step and the energies every 50 steps over 10^4 steps.
    """
    E, rho = 1e6, 1.0
    solid = box_solid((0, 0, 0), (10.0, 2.0, 1.0), (10, 2, 1), material(E=E, nu=0.0, rho=rho), gravity=(0, 0, -1.0),
                      element="P2", fixed=["xmin"])
    solid.static_solve()
    u = solid.displacement_vec
    Ku = u.duplicate()
    solid.stiffness.mult(u, Ku)
    mass = solid.lumped_mass.getArray()
    sag = u.getArray()
    # static-stiffness (Rayleigh) estimate of the first bending frequency from the static gravity deflection
    omega_rayleigh = np.sqrt(Ku.dot(u) / np.dot(mass * sag, sag))
    initial_strain_energy = 0.5 * Ku.dot(u)  # u is the solid's own Vec: evaluate before stepping
    solid.set_gravity((0.0, 0.0, 0.0))
    dt = solid.critical_time_step()
    tip = np.isclose(solid.reference_positions[:, 0], 10.0)

    tip_history, energies = [], []
    for n in range(10_000):
        solid.step(dt)
        tip_history.append(solid.displacements[tip[: solid.n_owned_nodes], 2].mean())
        if n % 50 == 0:
            energies.append(modified_energy(solid, dt))
    return dict(solid=solid, dt=dt, tip=np.array(tip_history), energies=np.array(energies), omega_rayleigh=omega_rayleigh,
                initial_strain_energy=initial_strain_energy)


def test_first_bending_frequency_matches_static_stiffness_estimate(released_cantilever):
    run = released_cantilever
    z, dt = run["tip"], run["dt"]
    t = dt * np.arange(1, len(z) + 1)
    i = np.flatnonzero(np.sign(z[:-1]) != np.sign(z[1:]))
    crossings = t[i] - z[i] * dt / (z[i + 1] - z[i])
    assert len(crossings) >= 3
    omega = np.pi / np.mean(np.diff(crossings))
    # Rayleigh's principle: the quotient of any shape bounds omega_1^2 from above; central difference
    # raises frequencies by (omega dt)^2 / 24 < 1e-6 here.  Below: the gravity sag is not exactly the
    # mode (measured 0.26 % lower; the discrete eigenvalue is 0.44 % lower; 1 % allowed).
    assert omega <= run["omega_rayleigh"] * (1 + 1e-6)
    assert omega >= run["omega_rayleigh"] * 0.99
    # Euler-Bernoulli 3.516 sqrt(EI / (rho A L^4)); shear and rotary inertia lower it ~1 % at L/h = 10
    euler_bernoulli = 3.516 * np.sqrt(1e6 * (2.0 / 12.0) / (1.0 * 2.0 * 10.0**4))
    assert 0.97 < omega / euler_bernoulli < 1.0


def test_undamped_free_vibration_conserves_energy_over_ten_thousand_steps(released_cantilever):
    run = released_cantilever
    modified, midpoint, kinetic = run["energies"].T
    # H is conserved exactly by the scheme: only round-off accumulates, a few eps (~1e-15) per step over
    # 10^4 steps in the worst (linear) case, 1e-11, plus ~1e-12 for evaluating H (sums over ~700 dofs; see
    # below): 2e-11 (measured 6.4e-12).
    assert np.abs(modified - modified[0]).max() <= 2e-11 * modified[0]
    # it equals the released strain energy (the first step starts from rest), to the round-off of the two
    # evaluations (measured 1.1e-12)
    assert modified[0] == pytest.approx(run["initial_strain_energy"], rel=1e-11)
    # physical energy: 0 <= E_mid - H = dt^2/8 v^T K v <= (omega_max dt)^2 / 4 * KE   (proven bound)
    omega_max_dt = run["solid"].largest_frequency_bound() * run["dt"]
    gap = midpoint - modified
    assert np.all(gap >= -1e-12 * modified[0])
    assert np.all(gap <= omega_max_dt**2 / 4 * kinetic + 1e-12 * modified[0])


def _true_largest_eigenvalue(solid):
    K = dense(solid.stiffness)
    if solid.lumped:
        m = solid.lumped_mass.getArray()
        return np.linalg.eigvalsh(K / np.sqrt(np.outer(m, m)))[-1]
    inverse_factor = np.linalg.inv(np.linalg.cholesky(dense(solid.consistent_mass)))
    return np.linalg.eigvalsh(inverse_factor @ K @ inverse_factor.T)[-1]


@pytest.mark.parametrize("element", ["P1", "P2"])
@pytest.mark.parametrize("mass", ["lumped", "consistent"])
def test_critical_step_bound_against_true_largest_eigenvalue(element, mass):
    solid = box_solid((0, 0, 0), (0.2, 0.1, 0.1), (2, 1, 1), material(E=2e11, nu=0.3, rho=7800.0), element=element, mass=mass)
    true = _true_largest_eigenvalue(solid)
    bound = solid.largest_frequency_bound() ** 2
    # proven: lambda_max(K, M) <= max_e lambda_max(K_e, M_e); 1e-12 for the eigensolvers' round-off
    assert true <= bound * (1 + 1e-12)
    # and not absurdly pessimistic: measured bound/true = 1.82 (P1 lumped), 2.31 (P1 consistent),
    # 1.25 (P2 lumped), 1.92 (P2 consistent)
    assert bound / true < 2.5
    assert solid.critical_time_step() == pytest.approx(2.0 / np.sqrt(bound), rel=1e-12)


def _free_block_with_random_velocity():
    solid = box_solid((0, 0, 0), (0.2, 0.1, 0.1), (2, 1, 1), material(E=2e11, nu=0.3, rho=7800.0))
    rng = np.random.default_rng(1)
    solid.set_state(np.zeros((solid.n_owned_nodes, 3)), 1e-3 * rng.standard_normal((solid.n_owned_nodes, 3)))
    return solid, 2.0 / np.sqrt(_true_largest_eigenvalue(solid))


def test_step_just_above_true_critical_blows_up_and_is_detected():
    solid, true_critical = _free_block_with_random_velocity()
    with pytest.raises(SolverError, match="blew up"):
        for _ in range(3000):  # growth per step ~1 + sqrt(8 * 0.02) = 1.4: detected in < 200 steps
            solid.step(1.02 * true_critical, check_stability=False)
    assert solid.step_count < 3000


def test_step_just_below_true_critical_stays_bounded():
    solid, true_critical = _free_block_with_random_velocity()
    kinetic0 = solid.kinetic_energy()
    for _ in range(3000):
        solid.step(0.98 * true_critical, check_stability=False)
    # no growth: with omega_max dt = 1.96 the half-step kinetic energy may exceed H by up to a factor
    # 1 / (1 - (omega dt)^2 / 4) = 25 in the top mode, never more
    assert solid.kinetic_energy() <= 25.5 * kinetic0


def test_step_above_the_bound_is_refused_with_the_numbers():
    solid, _ = _free_block_with_random_velocity()
    limit = solid.critical_time_step()
    solid.step(limit)  # at the bound: accepted
    with pytest.raises(SolverError, match=f"exceeds the critical central-difference step {limit:.4e}"):
        solid.step(1.01 * limit)
    assert solid.advance(3.5 * limit) == 4  # sub-cycling takes the fewest stable steps


def test_rayleigh_damping_dissipates_and_lowers_the_critical_step():
    common = dict(low=(0, 0, 0), high=(0.2, 0.1, 0.1), cells=(2, 1, 1), mat=material(E=2e11, nu=0.3, rho=7800.0))
    undamped = box_solid(**common)
    damped = box_solid(**common, damping={"alpha": 50.0, "beta": 1e-7})
    omega = damped.largest_frequency_bound()
    xi = 50.0 / (2 * omega) + 1e-7 * omega / 2
    assert damped.critical_time_step() == pytest.approx(undamped.critical_time_step() * (np.sqrt(1 + xi**2) - xi), rel=1e-12)
    rng = np.random.default_rng(2)
    velocity = 1e-3 * rng.standard_normal((damped.n_owned_nodes, 3))
    damped.set_state(np.zeros_like(velocity), velocity)
    energy0 = damped.kinetic_energy()
    for _ in range(500):
        damped.step(damped.critical_time_step())
    assert damped.kinetic_energy() + damped.strain_energy() < 0.5 * energy0


def test_nodal_forces_deliver_their_impulse_and_work():
    # a free block: one step with nodal forces F changes the momentum by sum(F) dt exactly (lumped mass)
    solid = box_solid((0, 0, 0), (0.2, 0.1, 0.1), (2, 1, 1), material(E=2e11, nu=0.3, rho=7800.0), contact=["zmax"])
    nodes, _, _ = solid.surface_state()
    forces = np.tile([1.0, -2.0, 3.0], (len(nodes), 1))
    dt = solid.critical_time_step()
    solid.add_nodal_forces(nodes, forces)
    solid.add_nodal_forces(nodes[:1], [[0.5, 0.0, 0.0]])  # adds up with the first call
    solid.step(dt)
    mass = solid.lumped_mass.getArray().reshape(-1, 3)
    momentum = (mass * solid.velocities).sum(axis=0)
    impulse = (forces.sum(axis=0) + [0.5, 0.0, 0.0]) * dt
    # Round-off: sums of ~30 nodal terms (forces, mass x velocity), <= 30 eps each way: 100 eps
    # (measured 1.1e-16 = 0.5 eps).
    round_off = 100 * np.finfo(float).eps
    assert np.allclose(momentum, impulse, rtol=round_off, atol=0)
    # work of the step: F . (u1 - u0) / 2 (midpoint rule with v_{-1/2} = 0)
    moved = solid.displacements
    expected_work = 0.5 * (np.sum(forces * moved[nodes]) + 0.5 * moved[nodes[0], 0])
    assert solid.external_work == pytest.approx(expected_work, rel=round_off)
    solid.step(dt)  # the forces were cleared after the step
    assert np.allclose((mass * solid.velocities).sum(axis=0), impulse, rtol=round_off, atol=0)
    # sub-cycled: the same forces act over the whole interval
    solid.add_nodal_forces(nodes, forces)
    substeps = solid.advance(2.5 * dt)
    assert substeps == 3
    assert np.allclose((mass * solid.velocities).sum(axis=0), impulse + forces.sum(axis=0) * 2.5 * dt, rtol=round_off,
                       atol=0)


@pytest.mark.parametrize("element", ["P1", "P2"])
def test_a_prescribed_velocity_books_the_work_it_feeds_in(element):
    """A bar clamped at x = 0 whose end x = L is pulled sideways at constant speed: the supports' work is
    the strain and kinetic energy it leaves in the bar.  The kernel books each step's reaction R^n on the
    increment dt (v- + v+) / 2 centred on u^n, while the strain energy is read at u^{n+1}: the half step
    dt v+ / 2 of the current reaction is added when the work is read.  Without it the books lag by
    R v dt / 2 = W / N at the end of a pull of N steps (W = R u / 2; measured 0.92-1.0 W / N).  What is left
    is central difference's own energy error, which oscillates with the bar's vibration (the pull's start rings
    it) and stays below 2 % of its kinetic energy: at N = 4000, 0.007 W / N (P1) and 0.002 W / N (P2), where the
    kinetic energy is 1e-4 W and 1e-3 W.  A tenth of W / N separates the two.  A held end's work is exactly 0."""
    speed = 0.05
    bar = box_solid((0, 0, 0), (0.1, 0.02, 0.01), (4, 1, 1), material(E=7e10, nu=0.33, rho=2700.0),
                    element=element, fixed=["xmin"], prescribed=[{"group": "xmax", "velocity": [0.0, 0.0, speed]}])
    held = box_solid((0, 0, 0), (0.1, 0.02, 0.01), (4, 1, 1), material(E=7e10, nu=0.33, rho=2700.0),
                     element=element, fixed=["xmin"], prescribed=[{"group": "xmax", "displacement": [0.0, 0.0, 1e-4]}])
    held.static_solve()
    dt = bar.critical_time_step()
    stored0 = bar.kinetic_energy() + bar.strain_energy()
    steps = 4000
    for _ in range(steps):
        bar.step(dt)
        held.step(dt)
    work = bar.support_work
    stored = bar.kinetic_energy() + bar.strain_energy() - stored0
    assert work > 0.0 and held.strain_energy() > 0.0
    assert abs(stored - work) < 0.1 * work / steps, (stored, work, work / steps)
    assert held.support_work == 0.0  # every constrained velocity is zero: each term is exactly 0


def test_a_prescribed_velocitys_work_restarts_bit_identical(tmp_path):
    from mpi4py import MPI

    from pdemfem.io.checkpoint import read_state, write_state

    def build():
        return box_solid((0, 0, 0), (0.1, 0.02, 0.01), (4, 1, 1), material(E=7e10, nu=0.33, rho=2700.0),
                         fixed=["xmin"], prescribed=[{"group": "xmax", "velocity": [0.0, 0.0, 0.05]}])

    straight, resumed = build(), build()
    dt = straight.critical_time_step()
    for _ in range(300):
        straight.step(dt)
        resumed.step(dt)
    straight.state_dict()  # a running simulation writes its checkpoint too: the books settle alike
    path = write_state(tmp_path / "s.h5", MPI.COMM_WORLD, {"solid": resumed.state_dict()})
    fresh = build()
    _, state = read_state(path, MPI.COMM_WORLD)
    fresh.load_state_dict(state["solid"])
    assert fresh.support_work == straight.support_work  # read before any step: the half step came back too
    for _ in range(200):
        straight.step(dt)
        fresh.step(dt)
    assert np.array_equal(fresh.displacements, straight.displacements)
    assert fresh.support_work == straight.support_work > 0.0


@pytest.mark.parametrize("alpha, beta_omega, mass", [(40.0, 0.0, "lumped"), (0.0, 1.0, "lumped"),
                                                     (40.0, 0.5, "consistent")])
def test_rayleigh_damping_books_the_energy_it_takes(alpha, beta_omega, mass):
    """A P1 cantilever set moving with random nodal velocities under Rayleigh damping (beta given as
    beta omega_max, the highest mode's share: 1 is a damping ratio of 0.5 there): central difference's
    modified energy H = 1/2 v^T (M - dt^2/4 K) v + 1/2 ubar^T K ubar (conserved exactly without damping; see
    test_undamped_free_vibration_conserves_energy_over_ten_thousand_steps) falls by exactly the work the
    kernel books for the damping forces alpha M vbar + beta K v- on the step's increment dt vbar.  So H plus
    damping_work stays constant to round-off: a few eps per step over 1500 steps, 1e-11 of H (the mass solve
    made exact with consistent mass: LU as CG's preconditioner; the default rtol 1e-8 would leave 1e-8 per
    step).  The damping must take a real share of the energy (more than half) for the check to mean anything."""
    from fem_helpers import petsc_options

    shape = dict(low=(0, 0, 0), high=(10.0, 2.0, 1.0), cells=(8, 2, 1), mat=material(E=1e6, nu=0.0, rho=1.0),
                 fixed=["xmin"], mass=mass)
    beta = beta_omega / box_solid(**shape).largest_frequency_bound()
    with petsc_options(fem_mass_pc_type="lu", fem_mass_ksp_rtol=1e-14):
        beam = box_solid(**shape, damping={"alpha": alpha, "beta": beta})
        velocities = np.random.default_rng(3).standard_normal((beam.n_owned_nodes, 3))
        velocities[beam.constrained_dofs.reshape(-1, 3)] = 0.0
        beam.set_state(np.zeros_like(velocities), velocities)
        dt = 0.9 * beam.critical_time_step()
        start = modified_energy(beam, dt)[0]
        largest_error = 0.0
        for n in range(1500):
            beam.step(dt)
            if n % 100 == 99:
                largest_error = max(largest_error, abs(modified_energy(beam, dt)[0] + beam.damping_work - start))
        assert beam.damping_work > 0.5 * start, (beam.damping_work, start)
        assert largest_error <= 1e-11 * start, (largest_error, start)

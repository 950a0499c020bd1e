"""Restitution calibration: the restitution a user sets is the restitution they get."""
import math
import time

import numpy as np
import pytest

from pdemfem.contact import restitution as rst
from pdemfem.contact.restitution import (
    MODELS,
    linear_damping_coefficient_unclamped,
    normal_damping_coefficient,
    restitution_from_damping,
    restitution_from_damping_ode,
    tsuji_damping_coefficient,
)

# Glass-like 1 mm sphere on a rigid wall (m* = m, R* = R), and a linear spring.
MASS = 2500.0 * 4.0 / 3.0 * math.pi * 1e-3**3
RADIUS = 1e-3
E_STAR = 3.5e10
K_LINEAR = 2e4


def verlet_restitution(model, gamma, v0, dt):
    """Dimensional head-on impact, velocity Verlet (half-kick, drift, force, half-kick).

    Independent of the module: SI units, the kernel's force laws written out, the
    dashpot taken implicitly in the end-of-step velocity (the force is linear in it,
    so the clamped update has a closed form).  Returns |v_sep| / v0.
    """
    m = MASS

    def spring_and_dashpot(d):
        if model == "hertz_mindlin":
            k = 4.0 / 3.0 * E_STAR * math.sqrt(RADIUS)
            s_n = 2.0 * E_STAR * math.sqrt(RADIUS * d)
            return k * d**1.5, gamma * math.sqrt(m * s_n)
        return K_LINEAR * d, gamma * math.sqrt(m * K_LINEAR)

    d, v = 0.0, v0  # overlap and approach rate
    a_spring, b_dash = spring_and_dashpot(d)
    f = max(0.0, a_spring + b_dash * v)
    for _ in range(10_000_000):
        v_half = v - 0.5 * dt * f / m
        d += dt * v_half
        if d <= 0.0:
            return -v_half / v0  # contact over; the clamp had already zeroed the force
        a_spring, b_dash = spring_and_dashpot(d)
        if a_spring + b_dash * v_half <= 0.0:
            v, f = v_half, 0.0
        else:
            v = (v_half - 0.5 * dt * a_spring / m) / (1.0 + 0.5 * dt * b_dash / m)
            f = a_spring + b_dash * v
    raise AssertionError("contact did not end")


def contact_time(model, v0):
    """Undamped contact duration (Hertz: 2.868 (m*^2/(R* E*^2 v))^(1/5); linear: pi sqrt(m/k))."""
    if model == "hertz_mindlin":
        return 2.868 * (MASS**2 / (RADIUS * E_STAR**2 * v0)) ** 0.2
    return math.pi * math.sqrt(MASS / K_LINEAR)


# Steps per undamped contact duration, and the resulting error bound of the Verlet
# check.  Linear: velocity Verlet is second order, |error| <= C (dt/t_c)^2; the constant
# measured over e in [0.02, 0.99] is at most 2.1 (largest for strong damping), C = 4.
# Hertz: the dashpot ~ delta^(1/4) is singular at first touch, which lowers the order
# to 5/4: |error| <= C (dt/t_c)^(5/4); measured constant at most 0.47, C = 1.
VERLET = {
    "linear_spring_dashpot": dict(steps=2000, tol=4.0 * (1 / 2000) ** 2),  # 1.0e-6
    "hertz_mindlin": dict(steps=4000, tol=1.0 * (1 / 4000) ** 1.25),  # 3.1e-5
}


@pytest.mark.parametrize("model", MODELS)
def test_forward_map_is_monotonic_from_one_to_zero(model):
    gammas = np.concatenate([[0.0], np.logspace(-6, 3, 400)])
    e = np.array([restitution_from_damping(model, g) for g in gammas])
    assert e[0] == 1.0
    assert np.all(np.diff(e) < 0.0), "restitution must fall strictly as damping grows"
    assert 0.0 < e[-1] < 1e-5  # every e in (0, 1) is reachable (e ~ 1/gamma^2)


def test_forward_map_is_continuous_across_critical_damping_branches():
    # zeta = 1 +/- 1e-3 is where the closed form switches to its series; an error in
    # either branch shows up as a jump far above the 1e-13 rounding level.
    for zeta_switch in (1.0 - 1e-3, 1.0 + 1e-3):
        inside = zeta_switch + (1e-9 if zeta_switch < 1.0 else -1e-9)
        outside = zeta_switch - (1e-9 if zeta_switch < 1.0 else -1e-9)
        e_in = restitution_from_damping("linear_spring_dashpot", 2.0 * inside)
        e_out = restitution_from_damping("linear_spring_dashpot", 2.0 * outside)
        slope = 2e-9 * 0.3  # |de/dzeta| ~ 0.3 near zeta = 1, times the 2e-9 separation
        assert abs(e_in - e_out) < slope + 1e-12, (zeta_switch, e_in, e_out)


@pytest.mark.parametrize("model", MODELS)
def test_full_restitution_gives_zero_damping(model):
    assert normal_damping_coefficient(model, 1.0) == 0.0
    assert restitution_from_damping(model, 0.0) == 1.0
    assert restitution_from_damping_ode(model, 0.0) == 1.0
    assert normal_damping_coefficient(model, 0.999) > 0.0


@pytest.mark.parametrize("model", MODELS)
def test_inverse_reproduces_target_through_forward_map(model):
    for e in [1e-6, 1e-3, 0.05, math.exp(-2.0), 0.1, 0.3, 0.5, 0.7, 0.9, 0.99, 1 - 1e-9]:
        gamma = normal_damping_coefficient(model, e)
        assert abs(restitution_from_damping(model, gamma) - e) < 1e-12 * max(e, 1e-3)


@pytest.mark.parametrize("model", MODELS)
def test_closed_form_agrees_with_integrated_ode(model):
    # The Hertz ODE is integrated in its own variables, so this also checks the
    # Hertz -> linear identity e_hertz(gamma) = e_linear(sqrt(6/5) gamma).
    # Dormand-Prince at tolerance 1e-12 per step: ~1e-10 in e (1e-9 asserted).
    # 2 (1 -/+ 5e-4): inside the series used around critical damping (zeta = 1).
    for gamma in [1e-3, 0.05, 0.3, 1.0, 1.8, 1.999, 2.0, 2.001, 2.2, 5.0, 20.0]:
        closed = restitution_from_damping(model, gamma)
        ode = restitution_from_damping_ode(model, gamma)
        assert abs(ode - closed) < 1e-9 * max(closed, 0.01), (gamma, closed, ode)


def test_ode_solver_without_clamp_matches_analytic_linear_formula():
    # Validates the ODE solver on the one case with a textbook answer.
    for gamma in [1e-3, 0.1, 0.5, 1.0, 1.5, 1.9]:
        zeta = gamma / 2.0
        analytic = math.exp(-zeta * math.pi / math.sqrt(1.0 - zeta**2))
        ode = restitution_from_damping_ode("linear_spring_dashpot", gamma, clamp=False)
        assert abs(ode - analytic) < 1e-10, (gamma, analytic, ode)
    for e in [0.1, 0.5, 0.9]:
        gamma = linear_damping_coefficient_unclamped(e)
        assert abs(restitution_from_damping_ode("linear_spring_dashpot", gamma, clamp=False) - e) < 1e-10


def test_textbook_hertz_value_is_exact_only_without_the_clamp():
    for e in [0.1, 0.5, 0.9]:
        gamma = tsuji_damping_coefficient(e)
        assert abs(restitution_from_damping_ode("hertz_mindlin", gamma, clamp=False) - e) < 1e-9
        assert restitution_from_damping("hertz_mindlin", gamma) > e + 1e-3  # clamp: too elastic
    # The numbers in docs/restitution.md.
    assert restitution_from_damping("hertz_mindlin", tsuji_damping_coefficient(0.1)) == pytest.approx(
        0.25273, abs=1e-5
    )
    assert restitution_from_damping("linear_spring_dashpot", linear_damping_coefficient_unclamped(0.5)) == (
        pytest.approx(0.55028, abs=1e-5)
    )


@pytest.mark.parametrize("model", MODELS)
@pytest.mark.parametrize("v0", [0.1, 1.0, 10.0])
def test_calibrated_damping_reproduces_restitution_in_dimensional_verlet(model, v0):
    steps, tol = VERLET[model]["steps"], VERLET[model]["tol"]
    dt = contact_time(model, v0) / steps
    for e in [0.1, 0.5, 0.9]:
        measured = verlet_restitution(model, normal_damping_coefficient(model, e), v0, dt)
        assert abs(measured - e) < tol, (e, measured, tol)  # tol: step-derived bound, see VERLET
    # The check is sharp enough to reject the uncalibrated textbook value.
    textbook = tsuji_damping_coefficient if model == "hertz_mindlin" else linear_damping_coefficient_unclamped
    assert abs(verlet_restitution(model, textbook(0.9), v0, dt) - 0.9) > 10 * tol


def test_verlet_bound_shrinks_with_the_step():
    # The tolerance above is only meaningful if the Verlet error follows the stated order.
    for model, p in [("hertz_mindlin", 1.25), ("linear_spring_dashpot", 2.0)]:
        gamma = normal_damping_coefficient(model, 0.1)
        t_c = contact_time(model, 1.0)
        errors = [abs(verlet_restitution(model, gamma, 1.0, t_c / n) - 0.1) for n in (500, 1000)]
        assert errors[1] < errors[0] * 2.0 ** (-p) * 1.2, (model, errors)


def test_calibration_is_cached_and_fast():
    rst._gamma_cached.cache_clear()
    t0 = time.perf_counter()
    gamma = normal_damping_coefficient("hertz_mindlin", 0.437)
    first = time.perf_counter() - t0
    hits = rst._gamma_cached.cache_info().hits
    assert normal_damping_coefficient("hertz_mindlin", 0.437) == gamma
    assert rst._gamma_cached.cache_info().hits == hits + 1
    assert first < 0.05


def test_bad_input_is_rejected():
    with pytest.raises(ValueError, match="unknown contact model"):
        normal_damping_coefficient("hertz", 0.5)
    for e in [0.0, -0.1, 1.2, float("nan")]:
        with pytest.raises(ValueError, match="restitution"):
            normal_damping_coefficient("hertz_mindlin", e)
    with pytest.raises(ValueError, match="damping"):
        restitution_from_damping("linear_spring_dashpot", -1.0)
    with pytest.raises(ValueError, match="overdamped"):
        restitution_from_damping_ode("linear_spring_dashpot", 2.5, clamp=False)

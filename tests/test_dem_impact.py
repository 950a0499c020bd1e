"""Verification: single normal and oblique impacts against analytic solutions.

Every case runs one or two spheres without gravity, records the overlap after each
step (positions are full-step values x^n of velocity Verlet) and compares with the
closed-form Hertz / linear-spring / impulse solutions.  Tolerances are derived in
the comments beside the asserts; docs/verification.md lists the measured errors.
"""
from __future__ import annotations

import math

import numpy as np
import pytest

from mpi_cases.dem_scenes import (GLASS, STEEL, effective_modulus, effective_shear_modulus, hertz_duration,
                                  hertz_duration_exact_factor, hertz_peak_overlap, single_sphere_on_floor,
                                  sphere_mass, two_spheres)
from pdemfem import Simulation
from pdemfem.contact.restitution import normal_damping_coefficient

# Steps of free flight before the contact; the fractional part puts the first touch
# in the middle of a step (not on a step boundary), the generic case.
APPROACH_STEPS = 4.37


def _crossing(t0, y0, t1, y1):
    """Time where the linear interpolant between (t0, y0) and (t1, y1) is zero."""
    return t0 + (t1 - t0) * y0 / (y0 - y1)


def _overlap_history(sim, overlap_of, max_steps):
    """Step until a contact has opened and closed again; return (times, overlaps)."""
    times = [sim.time]
    overlaps = [overlap_of(sim)]
    touched = False
    for _ in range(max_steps):
        sim.step(1)
        times.append(sim.time)
        overlaps.append(overlap_of(sim))
        touched = touched or overlaps[-1] > 0.0
        if touched and overlaps[-1] < 0.0:
            return np.array(times), np.array(overlaps)
    raise AssertionError("the contact did not close within max_steps")


def _measure(times, overlaps):
    """(peak overlap, contact duration) with interpolated start and end crossings.

    Near the crossings delta(t) = v (t - t0) + O(delta^(3/2)) is linear, so linear
    interpolation of the two crossings is accurate to O(dt^2) in time.  The peak is
    the largest sample refined by the parabola through it and its neighbours
    (error O(dt^3) instead of O(dt^2) for the raw sample).
    """
    inside = np.nonzero(overlaps > 0.0)[0]
    first, last = inside[0], inside[-1]
    start = _crossing(times[first - 1], overlaps[first - 1], times[first], overlaps[first])
    end = _crossing(times[last], overlaps[last], times[last + 1], overlaps[last + 1])
    k = int(np.argmax(overlaps))
    y0, y1, y2 = overlaps[k - 1], overlaps[k], overlaps[k + 1]
    curvature = y0 - 2.0 * y1 + y2
    peak = y1 - 0.125 * (y2 - y0) ** 2 / curvature if curvature < 0.0 else y1
    return peak, end - start


def _pair_overlap(sim):
    p = sim.particles
    order = np.argsort(p.ids)
    x, r = p.positions[order], p.radii[order]
    return r[0] + r[1] - float(np.linalg.norm(x[0] - x[1]))


def _wall_overlap(sim):
    p = sim.particles
    return float(p.radii[0] - p.positions[0, 2])


def _sphere_pair_case(material_a, material_b, radius_a, radius_b, speed, steps_per_contact, model="hertz_mindlin",
                      normal_stiffness=None, restitution=1.0, friction=0.0):
    """Head-on pair along z: a below moving up, b above moving down, relative speed `speed`.
    Returns (sim, m*, R*, E*, dt)."""
    m_a, m_b = sphere_mass(material_a, radius_a), sphere_mass(material_b, radius_b)
    m_eff = m_a * m_b / (m_a + m_b)
    r_eff = radius_a * radius_b / (radius_a + radius_b)
    e_eff = effective_modulus(material_a, material_b)
    if model == "hertz_mindlin" or normal_stiffness is None:
        duration = hertz_duration(m_eff, r_eff, e_eff, speed)
    else:
        duration = math.pi * math.sqrt(m_eff / normal_stiffness)
    dt = duration / steps_per_contact
    gap = APPROACH_STEPS * speed * dt
    # Unequal speeds: the centre-of-mass frame is not the lab frame.
    scene = two_spheres(radii=(radius_a, radius_b), materials=(material_a, material_b),
                        positions=[(0.0, 0.0, 0.0), (0.0, 0.0, radius_a + radius_b + gap)],
                        velocities=[(0.0, 0.0, 0.6 * speed), (0.0, 0.0, -0.4 * speed)], dt=dt, model=model,
                        restitution=restitution, friction=friction, normal_stiffness=normal_stiffness,
                        expected_impact_speed=speed)
    return Simulation.from_dict(scene), m_eff, r_eff, e_eff, dt


def _wall_case(material, wall_material, radius, speed, steps_per_contact, model="hertz_mindlin", restitution=1.0,
               normal_stiffness=None, tangential_speed=0.0, friction=0.0, duration=None):
    """Sphere falling (no gravity) onto the floor at normal speed `speed`.  Returns (sim, m*, R*, E*, dt)."""
    m_eff = sphere_mass(material, radius)
    e_eff = effective_modulus(material, wall_material)
    if duration is None:
        duration = (hertz_duration(m_eff, radius, e_eff, speed) if normal_stiffness is None
                    else math.pi * math.sqrt(m_eff / normal_stiffness))
    dt = duration / steps_per_contact
    scene = single_sphere_on_floor(radius=radius, material=material, wall_material=wall_material,
                                   velocity=(tangential_speed, 0.0, -speed),
                                   height=radius + APPROACH_STEPS * speed * dt, dt=dt, model=model,
                                   restitution=restitution, friction=friction, normal_stiffness=normal_stiffness,
                                   expected_impact_speed=speed)
    return Simulation.from_dict(scene), m_eff, radius, e_eff, dt


# ----------------------------------------------------------------------------- 1. Hertz


def test_hertz_duration_constant():
    # 2.868 is the rounded exact constant 2 (15/16)^(2/5) * (2/5) B(2/5, 1/2) = 2.86814...;
    # the rounding (2e-5 relative) is far below the 0.5 % the impact tests allow.
    assert abs(hertz_duration_exact_factor() / 2.868 - 1.0) < 1e-4


HERTZ_CASES = {
    "equal_spheres": ("pair", GLASS, GLASS, 1.0e-3, 1.0e-3),
    "unequal_spheres": ("pair", GLASS, STEEL, 1.0e-3, 1.5e-3),
    "sphere_on_wall": ("wall", GLASS, STEEL, 1.0e-3, None),
}


@pytest.mark.parametrize("case", sorted(HERTZ_CASES))
def test_hertz_elastic_impact(case):
    kind, material_a, material_b, radius_a, radius_b = HERTZ_CASES[case]
    speed = 1.0
    steps_per_contact = 200
    if kind == "pair":
        sim, m_eff, r_eff, e_eff, dt = _sphere_pair_case(material_a, material_b, radius_a, radius_b, speed,
                                                         steps_per_contact)
        times, overlaps = _overlap_history(sim, _pair_overlap, 4 * steps_per_contact)
    else:
        sim, m_eff, r_eff, e_eff, dt = _wall_case(material_a, material_b, radius_a, speed, steps_per_contact)
        times, overlaps = _overlap_history(sim, _wall_overlap, 4 * steps_per_contact)
    peak, duration = _measure(times, overlaps)
    peak_reference = hertz_peak_overlap(m_eff, r_eff, e_eff, speed)
    duration_reference = hertz_duration(m_eff, r_eff, e_eff, speed)
    # Velocity Verlet is second order: with omega = pi / t_c its phase and amplitude
    # errors are O((omega dt)^2) = (pi / 200)^2 = 2.5e-4; the crossing interpolation
    # adds O(dt^2) too, and 2.868 is rounded by 2e-5.  The 0.5 % is 20x that.
    tolerance = 5e-3
    assert abs(peak / peak_reference - 1.0) < tolerance, (peak, peak_reference)
    assert abs(duration / duration_reference - 1.0) < tolerance, (duration, duration_reference)
    # The same estimate, tighter: 4 (omega dt)^2 = 1e-3 -- fails if the scheme is only first order.
    second_order = 4.0 * (math.pi / steps_per_contact) ** 2
    assert abs(peak / peak_reference - 1.0) < second_order
    assert abs(duration / duration_reference - 1.0) < second_order + 2e-5


# ----------------------------------------------------------------------------- 7. linear spring


@pytest.mark.parametrize("kind", ["pair", "wall"])
def test_linear_spring_duration(kind):
    """Undamped linear spring: delta = v0 sqrt(m*/k) sin(t sqrt(k/m*)), contact for pi sqrt(m*/k)."""
    speed, stiffness, steps_per_contact = 0.5, 2.0e3, 200
    if kind == "pair":
        sim, m_eff, _, _, dt = _sphere_pair_case(GLASS, STEEL, 1.0e-3, 1.5e-3, speed, steps_per_contact,
                                                 model="linear_spring_dashpot", normal_stiffness=stiffness)
        times, overlaps = _overlap_history(sim, _pair_overlap, 4 * steps_per_contact)
    else:
        sim, m_eff, _, _, dt = _wall_case(GLASS, STEEL, 1.0e-3, speed, steps_per_contact,
                                          model="linear_spring_dashpot", normal_stiffness=stiffness)
        times, overlaps = _overlap_history(sim, _wall_overlap, 4 * steps_per_contact)
    peak, duration = _measure(times, overlaps)
    omega = math.sqrt(stiffness / m_eff)
    # Verlet on a harmonic oscillator: the frequency is exact up to (omega dt)^2 / 24 and
    # the amplitude up to (omega dt)^2 / 8 (shadow energy), with omega dt = pi / 200:
    # 3e-5.  The end crossing is interpolated on a sine: error (omega dt)^2 / 8 in the
    # phase.  Tolerance 2 (omega dt)^2 = 5e-4 covers their sum with margin.
    tolerance = 2.0 * (omega * dt) ** 2
    assert abs(duration * omega / math.pi - 1.0) < tolerance, (duration, math.pi / omega)
    assert abs(peak * omega / speed - 1.0) < tolerance, (peak, speed / omega)


# ----------------------------------------------------------------------------- 2. restitution


def _rebound_steps(damping_linear):
    """Steps per contact so that the discretisation error of the rebound ratio is <= 0.5 %.

    A first-order effect sets it (measured: error ~ dt, not dt^2): the dashpot
    uses the half-step velocity v^(n+1/2), lagging by dt/2 (the jump of the dashpot's
    force at first touch is applied as the continuous contact's mean now).  It changes
    the impulse by at most ~ gamma omega dt relative, omega dt = pi dt / t_c, gamma the
    equivalent linear coefficient (sqrt(6/5) gamma_hertz).  Requiring
    gamma pi / N <= 0.5 % gives N; at least the 100 steps of the brief.
    """
    return max(100, int(math.ceil(math.pi * damping_linear / 5e-3)))


@pytest.mark.parametrize("restitution", [0.2, 0.5, 0.9])
@pytest.mark.parametrize("speed", [0.1, 1.0, 10.0])
@pytest.mark.parametrize("kind", ["pair", "wall"])
@pytest.mark.parametrize("model", ["hertz_mindlin", "linear_spring_dashpot"])
def test_restitution(model, kind, speed, restitution):
    gamma = normal_damping_coefficient(model, restitution)
    gamma_linear = gamma * math.sqrt(1.2) if model == "hertz_mindlin" else gamma
    steps = _rebound_steps(gamma_linear)
    if kind == "pair":
        # Linear stiffness derived from the materials at `speed` (peak overlap = Hertz's),
        # so the contact lasts pi delta_max / v0 ~ 1.07 Hertz durations.
        sim, m_eff, r_eff, e_eff, dt = _sphere_pair_case(GLASS, STEEL, 1.0e-3, 1.5e-3, speed, steps, model=model,
                                                         restitution=restitution)
        approach = speed
        sim.step(int(APPROACH_STEPS) + 3 * steps)
        p = sim.particles
        v = p.velocities[np.argsort(p.ids), 2]
        separation = v[1] - v[0]
    else:
        sim, m_eff, r_eff, e_eff, dt = _wall_case(GLASS, STEEL, 1.0e-3, speed, steps, model=model,
                                                  restitution=restitution)
        approach = speed
        sim.step(int(APPROACH_STEPS) + 3 * steps)
        separation = sim.particles.velocities[0, 2]
    assert sim.contact_count() == 0, "the contact must have ended"
    measured = separation / approach
    # The issue asks for 1 %; asserted is the 0.5 % the step count was chosen for (the first-order
    # discretisation error, see _rebound_steps), the calibration itself being exact (1e-12).
    # Measured over the 36 cases: at most 1.1e-3 (Hertz, e = 0.2), independent of the speed.
    assert abs(measured / restitution - 1.0) < 5e-3, (measured, restitution, steps)


def _single_impact_at_dt_auto(model, gap):
    """The restitution of one head-on impact of two 5 mm rubber-like spheres at 1 m/s with dt: auto (e = 0.5),
    starting `gap` apart: the gap sets where in a step the contact begins; and the steps it lasted."""
    scene = {"time": {"end": 1.0, "dt": "auto"}, "gravity": [0, 0, 0],
             "materials": {"soft": {"density": 1100, "youngs_modulus": 5e6, "poisson_ratio": 0.45}},
             "interactions": {"default": {"model": model, "restitution": 0.5, "friction": 0.0}},
             "particles": [{"name": "p", "material": "soft", "radius": 0.005,
                            "insert": {"kind": "list", "positions": [[0, 0, 0], [0.01 + gap, 0, 0]],
                                       "velocities": [[0.5, 0, 0], [-0.5, 0, 0]]}}],
             "output": {"particles": [], "solids": []}}
    sim = Simulation.from_dict(scene)
    steps, started = 0, False
    while not started or sim.contact_count():
        sim.step(1)
        steps += bool(sim.contact_count())
        started = started or bool(sim.contact_count())
    velocities = sim.particles.velocities[np.argsort(sim.particles.ids), 0]
    return (velocities[1] - velocities[0]) / 1.0, steps


@pytest.mark.parametrize("model", ["linear_spring_dashpot", "hertz_mindlin"])
def test_a_single_impact_at_dt_auto_has_the_restitution_whatever_the_phase(model):
    """A dashpot's force jumps at first touch; applied for whole steps, single impacts at dt auto scattered
    around the asked restitution by where in a step they began: -3.0 .. +1.4 % (linear law, 33 steps per
    contact) and -1.1 .. +0.4 % (Hertz, 36 steps) over 12 start phases.  The first evaluation now applies the
    continuous contact's mean dashpot force over its window (pdemfem.contact.response.dashpot_onset)."""
    results = [_single_impact_at_dt_auto(model, 1e-4 * (1.0 + 0.37 * k / 6)) for k in range(6)]
    errors = np.array([measured / 0.5 - 1.0 for measured, _ in results])
    steps = min(count for _, count in results)
    # What is left depends on the phase at second order: the spring's onset, (omega dt)^2 / 8 of the impulse with
    # omega dt = pi / N, a few times.  Bound: (pi / N)^2 (0.9 % at N = 33; measured spread 0.04 % linear, 0.11 %
    # Hertz; before: 4.4 % and 1.5 %).
    assert errors.max() - errors.min() < (math.pi / steps) ** 2, (errors, steps)
    # And the promise of dt auto, for each impact now, not only on average: within 1 %.
    assert np.abs(errors).max() < 0.01, errors


# ----------------------------------------------------------------------------- 4. oblique impact

# The impulse solutions treat the sphere as rigid with lever R; the engine's lever is
# R - delta.  Stiff materials and a slow impact keep delta_max / R ~ 2e-3 so that the
# comparison tests the friction law, not the (correct) finite-overlap geometry.
HARD_GLASS = dict(GLASS, youngs_modulus=100.0 * GLASS["youngs_modulus"])
HARD_STEEL = dict(STEEL, youngs_modulus=100.0 * STEEL["youngs_modulus"])


def test_oblique_impact_sliding():
    """Gross sliding through the whole contact: F_t = -mu F_n t_hat at every instant, so the
    tangential impulse is mu times the normal impulse m (1 + e) v_n:

        v_t' = v_t - mu (1 + e) v_n,   w' = J_t R / I = (5/2) mu (1 + e) v_n / R.

    Sliding throughout needs the contact-point slip v_t - R w to stay positive:
    v_t > (7/2) mu (1 + e) v_n (here 3 v_n > 1.575 v_n).
    """
    radius, normal_speed, mu, e = 1.0e-3, 0.1, 0.3, 0.5
    tangential_speed = 3.0 * normal_speed
    gamma = normal_damping_coefficient("hertz_mindlin", e) * math.sqrt(1.2)
    steps = _rebound_steps(gamma)
    sim, m, _, e_eff, _ = _wall_case(HARD_GLASS, HARD_STEEL, radius, normal_speed, steps, restitution=e,
                                     friction=mu, tangential_speed=tangential_speed)
    sim.step(int(APPROACH_STEPS) + 3 * steps)
    p = sim.particles
    assert sim.contact_count() == 0
    rebound = p.velocities[0, 2] / normal_speed
    spin = p.angular_velocities[0, 1]
    # Normal rebound: within the 0.5 % discretisation bound of e (as test_restitution).
    assert abs(rebound / e - 1.0) < 5e-3
    # Impulse solution with the measured normal impulse m (v_n + v_n'): isolates the
    # friction law from the restitution error.  The tangential velocity is then exact
    # up to the first step of the contact, where the spring starts from zero below
    # mu F_n (a first-order onset effect, < 1/N of the impulse, N = steps per contact).
    # The spin sees the lever R - delta: relative effect < delta_max / R.
    impulse = mu * (1.0 + rebound) * normal_speed
    lever_error = hertz_peak_overlap(m, radius, e_eff, normal_speed) / radius
    assert lever_error < 5e-3  # the set-up keeps the geometric effect small (see HARD_GLASS)
    onset = 1.0 / steps
    assert abs(p.velocities[0, 0] - (tangential_speed - impulse)) < onset * impulse
    assert abs(spin / (2.5 * impulse / radius) - 1.0) < onset + lever_error, (spin, 2.5 * impulse / radius)
    # Against the nominal e as well: the impulse solution, plus the 0.5 % restitution error
    # scaled by e / (1 + e).
    nominal = mu * (1.0 + e) * normal_speed
    allowed = onset + 5e-3 * e / (1.0 + e)
    assert abs((tangential_speed - p.velocities[0, 0]) / nominal - 1.0) < allowed
    assert abs(spin / (2.5 * nominal / radius) - 1.0) < allowed + lever_error


def _tangential_rebound(model, angle_degrees):
    """(v_t' / v_t, steps in contact) of a 1 m/s impact at `angle_degrees` from the normal on a plane: an
    aluminium-like sphere (R 5 mm, E 70 GPa, nu 0.3) with e 0.5 and mu 0.3, ~390 steps per contact."""
    angle = math.radians(angle_degrees)
    material = {"density": 2700.0, "youngs_modulus": 7.0e10, "poisson_ratio": 0.3}
    dt = 1.0e-7
    scene = single_sphere_on_floor(radius=5e-3, material=material, velocity=(math.sin(angle), 0.0, -math.cos(angle)),
                                   height=5e-3 + 2e-6, dt=dt, model=model, restitution=0.5, friction=0.3,
                                   expected_impact_speed=1.0)
    sim = Simulation.from_dict(scene)
    touching = 0
    for _ in range(1200):
        sim.step(1)
        touching += sim.contact_count()
    assert sim.contact_count() == 0 and touching > 0
    return sim.particles.velocities[0, 0] / math.sin(angle), touching


@pytest.mark.parametrize("model, stiffness_ratio", [("linear_spring_dashpot", 2.0 / 7.0),
                                                    ("hertz_mindlin", 2.0 * (1.0 - 0.3) / (2.0 - 0.3))])
def test_tangential_rebound_is_continuous_where_the_dashpot_first_exceeds_the_coulomb_limit(model, stiffness_ratio):
    """At first touch the spring is unloaded, so both forces are the dashpots': the tangential one exceeds
    mu F_n from the first step on where tan(theta) > mu sqrt(S_n / S_t) (S_t / S_n: 2/7 for the linear
    model, 4 G*/E* = 2 (1 - nu) / (2 - nu) for Hertz-Mindlin).  The rebound must not jump there: a cap
    that stored the dashpot's part of the capped force in the spring gave it back as recoil, and the
    tangential rebound fell from 0.627 to 0.505 between 29.0 and 29.6 degrees (linear)."""
    threshold = math.degrees(math.atan(0.3 / math.sqrt(stiffness_ratio)))
    step = 0.3  # degrees
    rebounds = {}
    contact_steps = []
    for offset in (-3, -1, 1, 3):
        rebounds[offset], touching = _tangential_rebound(model, threshold + offset * step)
        contact_steps.append(touching)
    across = abs(rebounds[1] - rebounds[-1])
    beside = max(abs(rebounds[-1] - rebounds[-3]), abs(rebounds[3] - rebounds[1]))
    # A continuous response changes across the threshold about as much as over the same width beside it; the
    # time discretisation may move the start of slip by one step: at most 1/N of the tangential impulse
    # (< v_t), N the steps per contact.
    assert across < beside + 1.0 / min(contact_steps), (rebounds, min(contact_steps))


def _sticking_reference(m, radius, e_eff, g_eff, v_n, v_t, samples=20000):
    """No-slip elastic impact with the Mindlin spring F_t = -S_t(delta) xi, S_t = 8 G* sqrt(R delta),
    acting on the contact point's tangential motion (effective mass m I/(I + m R^2) = 2/7 m):

        m delta'' = -4/3 E* sqrt(R) delta^(3/2),   (2/7) m xi'' = -S_t(delta) xi,   xi'(0) = v_t.

    Integrated with classical RK4 on a fine grid (independent of the engine's Verlet);
    returns the contact-point slip velocity xi' at the end of the contact.
    """
    k = 4.0 / 3.0 * e_eff * math.sqrt(radius)
    mt = 2.0 / 7.0 * m

    def rhs(state):
        delta, ddelta, xi, dxi = state
        d = max(delta, 0.0)
        return np.array([ddelta, -k * d**1.5 / m, dxi, -8.0 * g_eff * math.sqrt(radius * d) * xi / mt])

    duration = hertz_duration(m, radius, e_eff, v_n)
    h = 1.2 * duration / samples
    state = np.array([0.0, v_n, 0.0, v_t])
    for _ in range(samples):
        k1 = rhs(state)
        k2 = rhs(state + 0.5 * h * k1)
        k3 = rhs(state + 0.5 * h * k2)
        k4 = rhs(state + h * k3)
        new = state + h / 6.0 * (k1 + 2 * k2 + 2 * k3 + k4)
        if new[0] < 0.0:
            return state[3]
        state = new
    raise AssertionError("reference contact did not end")


def test_oblique_impact_sticking():
    """Small tangential speed: the spring stays below mu F_n (at the touch S_t xi / F_n =
    6 (G*/E*) v_t / v_n = 0.06 < mu, and both grow alike), the contact point sticks and the
    outcome is the elastic Mindlin-spring solution (reference ODE, no slip).  Undamped
    (e = 1) so that the reference is the spring alone.

    Also exact in any regime: the angular momentum about the contact point,
    I w + m R v_t, is conserved (the contact force passes through that point).
    """
    radius, v_n, mu = 1.0e-3, 0.1, 0.5
    v_t = 0.05 * v_n
    steps = 400
    # nu = 0.45: the tangential oscillation then ends well away from a full period (for
    # nu = 0.3 it nearly completes one, slip' ~ 0.95 v_t, insensitive to the spring).
    ball, plate = dict(HARD_GLASS, poisson_ratio=0.45), dict(HARD_STEEL, poisson_ratio=0.45)
    sim, m, _, e_eff, dt = _wall_case(ball, plate, radius, v_n, steps, restitution=1.0, friction=mu,
                                      tangential_speed=v_t)
    sim.step(int(APPROACH_STEPS) + 3 * steps)
    p = sim.particles
    assert sim.contact_count() == 0
    v_out = p.velocities[0, 0]
    w_out = p.angular_velocities[0, 1]
    slip_out = v_out - radius * w_out
    reference = _sticking_reference(m, radius, e_eff, effective_shear_modulus(ball, plate), v_n, v_t)
    # A sliding contact would only reduce the slip by mu (1 + e) v_n (7/2) at most; sticking
    # leaves the reference value, which differs from v_t by much more than the tolerance below.
    assert abs(reference - v_t) > 0.2 * v_t
    # Engine vs reference: the spring is integrated with the half-step slip (first order in
    # the phase of the tangential oscillation, measured ~1/N), and the lever R - delta changes
    # the contact-point mass 2/7 m by < 5 delta_max / R = 1 %, the tangential frequency by half
    # that: 1/N + 2.5 delta_max / R of v_t.
    lever_error = hertz_peak_overlap(m, radius, e_eff, v_n) / radius
    tolerance = (1.0 / steps + 2.5 * lever_error) * v_t
    assert abs(slip_out - reference) < tolerance, (slip_out / v_t, reference / v_t)
    # Angular momentum about the contact point: only the lever R - delta breaks it,
    # d/dt (I w + m R v) = delta F_t, so |change| <= delta_max * (Coulomb bound on the tangential
    # impulse mu J_n, J_n = 2 m v_n for e = 1).
    inertia = 0.4 * m * radius**2
    bound = hertz_peak_overlap(m, radius, e_eff, v_n) * mu * 2.0 * m * v_n
    assert abs(inertia * w_out + m * radius * v_out - m * radius * v_t) < bound

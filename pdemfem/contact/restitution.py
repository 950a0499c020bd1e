r"""Normal damping coefficient from a coefficient of restitution, calibrated exactly.

The kernel's normal force laws (repulsive magnitude, overlap ``delta >= 0``,
approach rate ``delta_dot > 0`` while approaching, effective mass ``m*``,
radius ``R*``, modulus ``E*``), both clamped so that they never attract::

    hertz_mindlin:          F = max(0, k delta^(3/2) + gamma sqrt(m* S_n) delta_dot),
                            k = 4/3 E* sqrt(R*),  S_n = 2 E* sqrt(R* delta) = 1.5 k sqrt(delta)
    linear_spring_dashpot:  F = max(0, k delta + gamma sqrt(m* k) delta_dot)

A head-on impact is ``m* delta'' = -F``, ``delta(0) = 0``, ``delta'(0) = v0``; the
restitution is ``e = |delta'(t_sep)| / v0`` where ``delta(t_sep) = 0`` again.

1. Non-dimensionalisation (``e`` depends on ``gamma`` only)
-----------------------------------------------------------
Write ``delta = L x`` and ``t = (L / v0) tau`` so that ``x'(0) = 1``.

* Hertz: choose ``L = (m* v0^2 / k)^(2/5)`` (the scale of the maximum overlap).
  Dividing ``m* delta''`` by ``m* v0^2 / L``, the spring term becomes
  ``k L^(5/2) / (m* v0^2) * x^(3/2) = x^(3/2)`` and the dashpot term
  ``gamma sqrt(1.5 k m*) L^(1/4) x^(1/4) v0 x' L / (m* v0^2)
  = sqrt(1.5) gamma sqrt(k L^(5/2) / (m* v0^2)) x^(1/4) x' = sqrt(1.5) gamma x^(1/4) x'``::

      x'' = -max(0, x^(3/2) + sqrt(1.5) gamma x^(1/4) x'),   x(0) = 0, x'(0) = 1.

* Linear: choose ``L = v0 sqrt(m* / k)`` (time unit ``sqrt(m*/k)``)::

      y'' = -max(0, y + gamma y'),   y(0) = 0, y'(0) = 1.

Neither equation contains ``m*``, ``R*``, ``E*``, ``k`` or ``v0``, so ``e`` (minus
the final dimensionless velocity) is a function of ``gamma`` alone, for each law and
at any impact speed.

2. Hertz is the linear law in disguise
--------------------------------------
Map the Hertz solution by ``y = sqrt(4/5) x^(5/4)`` and a new time ``s`` with
``ds/dtau = (sqrt(5)/2) x^(1/4)``.  Then ``dy/ds = x'`` (velocities are unchanged), the
undamped energy ``x'^2/2 + (2/5) x^(5/2)`` becomes ``(dy/ds)^2/2 + y^2/2``, and::

      d(x')/ds = -(2/sqrt(5)) x^(5/4) - (2/sqrt(5)) sqrt(1.5) gamma x'
               = -(y + sqrt(6/5) gamma dy/ds),

including the clamp, because the Hertz force is ``x^(1/4)`` (>= 0) times
``x^(5/4) + sqrt(1.5) gamma x'``, which has the sign of ``y + sqrt(6/5) gamma dy/ds``.
``y = 0`` exactly when ``x = 0``, so the impact and separation velocities coincide::

      e_hertz(gamma) = e_linear(sqrt(6/5) gamma)     (exactly),

which is where the factor ``2 sqrt(5/6)`` of the textbook (Tsuji) formula comes
from.  The textbook formula is therefore exact for the unclamped Hertz law, and it
misses for the clamped law by exactly as much as ``gamma = 2 zeta`` misses for the
clamped linear law.

3. The clamped linear law in closed form
----------------------------------------
With ``zeta = gamma / 2`` the unclamped solution is
``y = exp(-zeta tau) sin(omega tau) / omega``, ``omega = sqrt(1 - zeta^2)``.  Without
the clamp the contact ends at ``y = 0``, ``tau = pi / omega``, so
``e = exp(-zeta pi / omega)`` and ``zeta = -ln e / sqrt(ln^2 e + pi^2)``.

With the clamp the force ``y + 2 zeta y'`` first vanishes during unloading (``y > 0``).
From then on ``y' < 0`` is constant and ``y`` shrinks, so ``y + 2 zeta y'`` keeps
decreasing: the force stays zero and the particle flies freely to ``y = 0``
(likewise ``x^(5/4) + sqrt(1.5) gamma x'`` for Hertz).  Hence ``e = -y'`` at the first
zero of ``y + 2 zeta y'``.  Substituting the solution, that zero is at
``cos(omega tau*) = 2 zeta^2 - 1``, ``sin(omega tau*) = 2 zeta omega``, i.e.
``omega tau* = 2 arccos(zeta)``, where ``y' = -exp(-zeta tau*)``::

      e = exp(-2 zeta arccos(zeta) / sqrt(1 - zeta^2))       zeta < 1
      e = exp(-2)                                             zeta = 1
      e = exp(-2 zeta arccosh(zeta) / sqrt(zeta^2 - 1))      zeta > 1  (same analytic function)

Since ``2 arccos(zeta) < pi`` the clamp always raises ``e``; every ``e`` in (0, 1) is
reached (``e ~ 1/gamma^2`` for large ``gamma``), so strongly damped contacts need
``gamma`` well above the overdamped limit 2 of the unclamped law.

Numerics
--------
``restitution_from_damping`` evaluates the closed form (relative accuracy ~1e-15);
``normal_damping_coefficient`` inverts it by bisection on ``zeta`` to machine
precision (well inside ``|e(gamma) - e_target| < 1e-12``) and caches the result.
``restitution_from_damping_ode`` integrates the dimensionless equations of section 1
directly (adaptive Dormand-Prince 5(4), tolerances 1e-12, end of contact located by
re-stepping onto the zero of the force; ~1e-10 in ``e``).  It shares no code with the
closed form and checks it, and the Hertz identity of section 2, in the tests.
"""
from __future__ import annotations

import math
from functools import lru_cache

__all__ = [
    "MODELS",
    "normal_damping_coefficient",
    "restitution_from_damping",
    "restitution_from_damping_ode",
    "tsuji_damping_coefficient",
    "linear_damping_coefficient_unclamped",
]

MODELS = ("hertz_mindlin", "linear_spring_dashpot")

_SQRT_1_5 = math.sqrt(1.5)
_RTOL = 1e-12
_ATOL = 1e-12

# Dormand-Prince 5(4) tableau (the ODE is autonomous, so the nodes c_i are not needed).
_A21 = 1 / 5
_A31, _A32 = 3 / 40, 9 / 40
_A41, _A42, _A43 = 44 / 45, -56 / 15, 32 / 9
_A51, _A52, _A53, _A54 = 19372 / 6561, -25360 / 2187, 64448 / 6561, -212 / 729
_A61, _A62, _A63, _A64, _A65 = 9017 / 3168, -355 / 33, 46732 / 5247, 49 / 176, -5103 / 18656
_B1, _B3, _B4, _B5, _B6 = 35 / 384, 500 / 1113, 125 / 192, -2187 / 6784, 11 / 84
# Error weights b - b_hat (b_hat: 5179/57600, 0, 7571/16695, 393/640, -92097/339200, 187/2100, 1/40).
_E1 = 35 / 384 - 5179 / 57600
_E3 = 500 / 1113 - 7571 / 16695
_E4 = 125 / 192 - 393 / 640
_E5 = -2187 / 6784 + 92097 / 339200
_E6 = 11 / 84 - 187 / 2100
_E7 = -1 / 40


def _check_model(model: str) -> str:
    """The damping law (one of MODELS) of a law or of a registered normal model's name."""
    if model in MODELS:
        return model
    from pdemfem.contact.registry import NORMAL_BY_NAME

    if model in NORMAL_BY_NAME:
        return NORMAL_BY_NAME[model].DAMPING_LAW
    raise ValueError(f"unknown contact model {model!r}; expected one of {', '.join(sorted(NORMAL_BY_NAME))}")


def _accel(hertz: bool, c: float, x: float, v: float) -> float:
    """Unclamped dimensionless acceleration -(spring + dashpot)."""
    if hertz:
        xp = x if x > 0.0 else 0.0
        r = math.sqrt(math.sqrt(xp))  # x^(1/4)
        return -(xp * r * r + c * r * v)  # x^(3/2) + c x^(1/4) v
    return -(x + c * v)


def _gap(hertz: bool, c: float, x: float, v: float, clamp: bool) -> float:
    """Event function: contact (or positive force) persists while it is > 0."""
    if not clamp:
        return x
    if hertz:
        xp = x if x > 0.0 else 0.0
        return xp * math.sqrt(math.sqrt(xp)) + c * v  # x^(5/4) + c v
    return x + c * v


def _dp_step(hertz, c, x, v, a1, h):
    """One Dormand-Prince step from (x, v) with acceleration a1 there.

    Returns x, v, a at the new state and the scaled error norm.
    """
    # Stage derivatives of (x, v) are (v_i, a_i).
    v1 = v
    x2 = x + h * _A21 * v1
    w2 = v + h * _A21 * a1
    a2 = _accel(hertz, c, x2, w2)
    x3 = x + h * (_A31 * v1 + _A32 * w2)
    w3 = v + h * (_A31 * a1 + _A32 * a2)
    a3 = _accel(hertz, c, x3, w3)
    x4 = x + h * (_A41 * v1 + _A42 * w2 + _A43 * w3)
    w4 = v + h * (_A41 * a1 + _A42 * a2 + _A43 * a3)
    a4 = _accel(hertz, c, x4, w4)
    x5 = x + h * (_A51 * v1 + _A52 * w2 + _A53 * w3 + _A54 * w4)
    w5 = v + h * (_A51 * a1 + _A52 * a2 + _A53 * a3 + _A54 * a4)
    a5 = _accel(hertz, c, x5, w5)
    x6 = x + h * (_A61 * v1 + _A62 * w2 + _A63 * w3 + _A64 * w4 + _A65 * w5)
    w6 = v + h * (_A61 * a1 + _A62 * a2 + _A63 * a3 + _A64 * a4 + _A65 * a5)
    a6 = _accel(hertz, c, x6, w6)
    xn = x + h * (_B1 * v1 + _B3 * w3 + _B4 * w4 + _B5 * w5 + _B6 * w6)
    vn = v + h * (_B1 * a1 + _B3 * a3 + _B4 * a4 + _B5 * a5 + _B6 * a6)
    an = _accel(hertz, c, xn, vn)
    ex = h * (_E1 * v1 + _E3 * w3 + _E4 * w4 + _E5 * w5 + _E6 * w6 + _E7 * vn)
    ev = h * (_E1 * a1 + _E3 * a3 + _E4 * a4 + _E5 * a5 + _E6 * a6 + _E7 * an)
    sx = _ATOL + _RTOL * max(abs(x), abs(xn))
    sv = _ATOL + _RTOL * max(abs(v), abs(vn))
    err = max(abs(ex) / sx, abs(ev) / sv)
    return xn, vn, an, err


def _separation_speed(model: str, gamma: float, clamp: bool = True) -> float:
    """-x' at the end of the dimensionless contact (see the module docstring)."""
    hertz = model == "hertz_mindlin"
    c = _SQRT_1_5 * gamma if hertz else gamma
    if not clamp and (c if not hertz else c * math.sqrt(0.8)) >= 2.0:
        raise ValueError("without the clamp an overdamped contact never separates")
    x, v = 0.0, 1.0
    a = _accel(hertz, c, x, v)
    # Initial step: small, the x^(1/4) term is singular at tau = 0.
    h = 1e-4 / (1.0 + c)
    for _ in range(200000):
        xn, vn, an, err = _dp_step(hertz, c, x, v, a, h)
        if err <= 1.0:
            g_new = _gap(hertz, c, xn, vn, clamp)
            if g_new <= 0.0:
                return -_locate_event(hertz, c, x, v, a, h, clamp)
            x, v, a = xn, vn, an
        fac = 0.9 * err ** (-0.2) if err > 0.0 else 5.0
        h *= min(5.0, max(0.2, fac))
    raise RuntimeError(f"contact ODE did not end (model={model}, gamma={gamma})")


def _locate_event(hertz, c, x, v, a, h, clamp) -> float:
    """Velocity at the zero of the event function inside the step (0, h] from (x, v)."""
    g_lo = _gap(hertz, c, x, v, clamp)
    lo, hi = 0.0, h
    v_lo = v
    xn, vn, _, _ = _dp_step(hertz, c, x, v, a, hi)
    g_hi = _gap(hertz, c, xn, vn, clamp)
    v_hi = vn
    side = 0
    for _ in range(200):
        if g_hi == 0.0:
            return v_hi
        if g_lo - g_hi == 0.0:
            break
        m = hi - g_hi * (hi - lo) / (g_hi - g_lo)
        if not (lo < m < hi):
            m = 0.5 * (lo + hi)
        xm, vm, _, _ = _dp_step(hertz, c, x, v, a, m)
        gm = _gap(hertz, c, xm, vm, clamp)
        if gm > 0.0:
            lo, g_lo, v_lo = m, gm, vm
            if side == -1:
                g_hi *= 0.5
            side = -1
        else:
            hi, g_hi, v_hi = m, gm, vm
            if side == 1:
                g_lo *= 0.5
            side = 1
        if hi - lo <= 1e-15 * max(1.0, hi):
            break
    return v_hi if abs(g_hi) <= abs(g_lo) else v_lo


def restitution_from_damping_ode(model: str, gamma: float, clamp: bool = True) -> float:
    """Restitution from integrating the dimensionless contact ODE (independent check).

    ``clamp=False`` lets the force turn attractive and ends the contact at zero
    overlap (underdamped only: ``gamma < 2``, Hertz ``gamma < 2 sqrt(5/6)``), for
    comparison with the analytic ``exp(-zeta pi / sqrt(1 - zeta^2))`` and the
    textbook Hertz value, which is exact in that case.
    """
    gamma = _check_gamma(gamma)
    if gamma == 0.0:
        return 1.0
    return _separation_speed(_check_model(model), gamma, clamp)


def _check_gamma(gamma) -> float:
    gamma = float(gamma)
    if not (gamma >= 0.0 and math.isfinite(gamma)):
        raise ValueError(f"damping coefficient must be finite and >= 0, got {gamma}")
    return gamma


def _check_restitution(e) -> float:
    e = float(e)
    if not 0.0 < e <= 1.0:
        raise ValueError(f"coefficient of restitution must be in (0, 1], got {e}")
    return e


def _arccos_ratio(zeta: float) -> float:
    """arccos(zeta)/sqrt(1-zeta^2), continued as arccosh(zeta)/sqrt(zeta^2-1) for zeta > 1."""
    u = 1.0 - zeta
    if abs(u) < 1e-3:  # removable singularity at zeta = 1; truncation ~ u^4 < 1e-12
        return 1.0 + u * (1.0 / 3.0 + u * (2.0 / 15.0 + u * (68.0 / 945.0)))
    if zeta < 1.0:
        return math.acos(zeta) / math.sqrt((1.0 - zeta) * (1.0 + zeta))
    return math.acosh(zeta) / math.sqrt((zeta - 1.0) * (zeta + 1.0))


def _neg_ln_e_linear(zeta: float) -> float:
    """-ln e of the clamped linear law with gamma = 2 zeta (module docstring, section 3)."""
    return 2.0 * zeta * _arccos_ratio(zeta)


def _linear_gamma(model: str, gamma: float) -> float:
    """The equivalent linear coefficient (section 2): sqrt(6/5) gamma for Hertz."""
    return gamma * math.sqrt(6.0 / 5.0) if model == "hertz_mindlin" else gamma


def restitution_from_damping(model: str, gamma: float) -> float:
    """Restitution produced by the dimensionless damping coefficient ``gamma`` (forward map).

    Exact closed form for the clamped law; ``gamma = 0`` gives 1.
    """
    gamma = _check_gamma(gamma)
    zeta = 0.5 * _linear_gamma(_check_model(model), gamma)
    return math.exp(-_neg_ln_e_linear(zeta))


def normal_damping_coefficient(model: str, restitution: float) -> float:
    """Dimensionless ``gamma`` for which the clamped force law yields ``restitution``.

    ``model`` is ``"hertz_mindlin"`` (dashpot ``gamma sqrt(m* S_n) delta_dot``) or
    ``"linear_spring_dashpot"`` (dashpot ``gamma sqrt(m* k) delta_dot``);
    ``0 < restitution <= 1``, and ``restitution == 1`` returns 0.  The result does not
    depend on masses, radii, moduli or impact speed.  Cached.
    """
    return _gamma_cached(_check_model(model), _check_restitution(restitution))


@lru_cache(maxsize=1024)
def _gamma_cached(model: str, e: float) -> float:
    if e == 1.0:
        return 0.0
    target = -math.log(e)  # > 0; -ln e(zeta) increases monotonically from 0 to infinity
    lo, hi = 0.0, 1.0
    while _neg_ln_e_linear(hi) < target:
        lo, hi = hi, 2.0 * hi
    for _ in range(200):  # bisection to adjacent floats
        mid = 0.5 * (lo + hi)
        if not lo < mid < hi:
            break
        if _neg_ln_e_linear(mid) < target:
            lo = mid
        else:
            hi = mid
    zeta = lo if abs(_neg_ln_e_linear(lo) - target) <= abs(_neg_ln_e_linear(hi) - target) else hi
    gamma_linear = 2.0 * zeta
    return gamma_linear * math.sqrt(5.0 / 6.0) if model == "hertz_mindlin" else gamma_linear


def _zeta_unclamped(e: float) -> float:
    le = math.log(e)
    return -le / math.sqrt(le * le + math.pi * math.pi)


def tsuji_damping_coefficient(restitution: float) -> float:
    """Textbook Hertz value ``2 sqrt(5/6) |ln e| / sqrt(ln^2 e + pi^2)``.

    Exact only without the clamp; with it the contact is more elastic than asked
    (see docs/restitution.md).  For comparison only.
    """
    return 2.0 * math.sqrt(5.0 / 6.0) * _zeta_unclamped(_check_restitution(restitution))


def linear_damping_coefficient_unclamped(restitution: float) -> float:
    """Analytic linear value ``gamma = 2 zeta``, exact only without the clamp."""
    return 2.0 * _zeta_unclamped(_check_restitution(restitution))

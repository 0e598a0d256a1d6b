"""The full force model and its DOP853 integration compiled with numba (a dependency; numpy path beside it).

The same physics as the numpy path, term for term and in the same order of summation where it
matters, so that the two agree to rounding: the field by the normalised Cunningham recursion of
:mod:`~trackproc.dynamics.forces.gravity_field` (Montenbruck & Gill 2000 eqs. 3.27-3.33), Sun
and Moon (eq. 3.37), SRP with the conical shadow (eqs. 3.75, 3.79-3.86), Harris-Priester drag
(eqs. 3.97, 3.99-3.104), the Schwarzschild term (IERS 2010 eq. 10.12), the empirical
accelerations, the Jacobians of
:meth:`~trackproc.dynamics.forces.model.Environment.partials`, and scipy's DOP853 (Hairer,
Nørsett & Wanner, *Solving ODEs I*, II.5: the same coefficients, error norm, step-size
controller and first-step guess) with the variational equations (M&G eqs. 7.42-7.44), all in
one compiled loop: no Python per right-hand-side call.

:func:`integrate` returns each accepted step's dense-output coefficients; the caller
(:func:`trackproc.dynamics.forces.integrator.propagate`) turns them into the step polynomials
exactly as for scipy's steps. One difference in method: ``∂a/∂r`` of the field and of Sun and
Moon is analytic here (:func:`hessian_tables`), by central differences on the numpy path. Only
the Harris-Priester atmosphere is compiled (NRLMSIS stays on the numpy path). Imported only when
:func:`trackproc.dynamics.jit.enabled`.

One module over 400 lines, on purpose: numba's on-disk cache is keyed on the file that defines a
kernel and does not follow the kernels it calls in other files (an edit there would leave a
stale compiled caller), so the kernels that call each other (field, bodies, shadow, drag, right-hand
side, integrator) live in one file.
"""

from __future__ import annotations

import math

import numpy as np

from trackproc.constants import C_LIGHT, OMEGA_EARTH, WGS84_A, WGS84_F
from trackproc.dynamics.forces import dop853_tableau as _dc
from trackproc.dynamics.forces import drag as drag_mod
from trackproc.dynamics.forces import srp, third_body
from trackproc.dynamics.jit import compile_once, njit
from trackproc.dynamics.forces.tables import (  # noqa: F401 - the kernels' cfg slots; the table builders re-exported
    _AM_DRAG, _AM_SRP, _CD, _CR, _DRAG, _ER, _EX, _EXR, _FLAT, _GM, _GRID, _HPN, _MOON, _NCFG, _NNODES, _RE, _REL,
    _SRP, _SUN, _T0, environment_tables, field_tables, hessian_tables, stm_field, supported)

__all__ = ["supported", "field_tables", "environment_tables", "integrate", "perturbation", "partials"]

# DOP853 tableau (scipy's copy of Hairer's coefficients)
_NS = _dc.N_STAGES
_A = np.ascontiguousarray(_dc.A)
_B = np.ascontiguousarray(_dc.B)
_C = np.ascontiguousarray(_dc.C)
_E3 = np.ascontiguousarray(_dc.E3)
_E5 = np.ascontiguousarray(_dc.E5)
_D = np.ascontiguousarray(_dc.D)
_SAFETY, _MIN_FACTOR, _MAX_FACTOR = 0.9, 0.2, 10.0
_EVENT_PAST_S = 1e-6                   # integrator.EVENT_PAST_S

_GM_SUN, _GM_MOON, _AU = third_body.GM_SUN, third_body.GM_MOON, third_body.AU_M
_P_SUN, _R_SUN = srp.P_SUN, srp.R_SUN
_HP_H = np.ascontiguousarray(drag_mod.HP_TABLE[:, 0] * 1e3)
_HP_LMIN = np.log(drag_mod.HP_TABLE[:, 1] * 1e-12)
_HP_LMAX = np.log(drag_mod.HP_TABLE[:, 2] * 1e-12)
_LAG = drag_mod.LAG_RAD



#: kernels only other kernels call: no CPython wrapper (numba would compile one for each); never
#: call one from Python (it would crash the process; tests/dynamics/test_compiled_inner_kernels.py)
_INNER = dict(no_cpython_wrapper=True)


# -- forces ----------------------------------------------------------------------------------
@njit(**_INNER)
def _solid_harmonics(r, a, b, fprod, nmax, mmax, R):
    """The normalised solid harmonics ``Z[n, m]`` (n <= nmax, m <= mmax) at ITRF ``r`` by the
    Cunningham recursion (Montenbruck & Gill 2000 eqs. 3.29-3.30, normalised as
    GravityField.acceleration); shared by the acceleration and its gradient."""
    x, y, z = r[0], r[1], r[2]
    r2 = x * x + y * y + z * z
    x0, y0, z0 = x * (R / r2), y * (R / r2), z * (R / r2)
    rho = R * R / r2
    Z = np.zeros((nmax + 1, nmax + 1), np.complex128)
    w = complex(x0, y0)
    p = 1.0 + 0.0j
    ron = R / math.sqrt(r2)
    for m in range(mmax + 1):
        Z[m, m] = fprod[m] * p * ron
        p = p * w
    for n in range(1, nmax + 1):
        for m in range(min(n, mmax + 1)):
            zn = a[n, m] * z0 * Z[n - 1, m]
            if n >= 2:
                zn = zn - b[n, m] * rho * Z[n - 2, m]
            Z[n, m] = zn
    return Z


@njit(**_INNER)
def _field_acc(r, F, central, out):
    """Field acceleration at ITRF ``r`` (3,) into ``out`` (normalised Cunningham recursion,
    Montenbruck & Gill 2000 eqs. 3.27-3.33, as GravityField.acceleration)."""
    a, b, fprod, p1, p2, p3, nn, mm, dims, consts = F
    gm, R = consts[0], consts[1]
    Z = _solid_harmonics(r, a, b, fprod, dims[0], dims[1], R)
    s1 = 0.0j
    s2 = 0.0j
    s3 = 0.0
    for j in range(0 if central else 1, nn.size):
        n, m = nn[j], mm[j]
        s1 += Z[n + 1, m + 1] * p1[j]
        s2 += Z[n + 1, max(m - 1, 0)].conjugate() * p2[j]
        s3 += (Z[n + 1, m] * p3[j]).real
    g = gm / (R * R)
    axy = s1 + s2
    out[0], out[1], out[2] = g * axy.real, g * axy.imag, g * s3


@njit(**_INNER)
def _mat3(a, b):
    out = np.empty((3, 3))
    for i in range(3):
        for j in range(3):
            out[i, j] = a[i, 0] * b[0, j] + a[i, 1] * b[1, j] + a[i, 2] * b[2, j]
    return out


@njit(**_INNER)
def _mv(m, x):
    return np.array([m[0, 0] * x[0] + m[0, 1] * x[1] + m[0, 2] * x[2], m[1, 0] * x[0] + m[1, 1] * x[1] + m[1, 2] * x[2],
                     m[2, 0] * x[0] + m[2, 1] * x[1] + m[2, 2] * x[2]])


@njit
def _field_hessian(r, HT, out):
    """``∂a/∂r`` of the field (no central term) at ITRF ``r`` into ``out`` (3, 3): the solid
    harmonics to degree N+2 by the same normalised recursion, weighted by hessian_tables."""
    H, a, b, fprod, dims, consts = HT
    nmax, mmax = dims[0], dims[1]
    gm, R = consts[0], consts[1]
    Z = _solid_harmonics(r, a, b, fprod, nmax, mmax, R)
    g = gm / (R * R * R)
    v = np.zeros(6)
    for k in range(6):
        acc = 0.0
        for n in range(nmax + 1):
            for m in range(min(n, mmax) + 1):
                acc += (H[k, n, m] * Z[n, m]).real
        v[k] = g * acc
    out[0, 0], out[0, 1], out[0, 2] = v[0], v[1], v[2]
    out[1, 0], out[1, 1], out[1, 2] = v[1], v[3], v[4]
    out[2, 0], out[2, 1], out[2, 2] = v[2], v[4], v[5]


@njit(**_INNER)
def _point_mass_gradient(r, body, gm, g):
    """∂/∂r of M&G eq. 3.37: ``GM (3 d dᵀ/|d|⁵ - I/|d|³)``, d = body - r, added to ``g``."""
    d = (body[0] - r[0], body[1] - r[1], body[2] - r[2])
    dn = math.sqrt(d[0] ** 2 + d[1] ** 2 + d[2] ** 2)
    for i in range(3):
        for j in range(3):
            g[i, j] += gm * (3.0 * d[i] * d[j] / dn ** 5 - (1.0 if i == j else 0.0) / dn ** 3)


@njit(**_INNER)
def _hermite(tab, k, x, h, out):
    x2, x3 = x * x, x * x * x
    for i in range(3):
        out[i] = ((2 * x3 - 3 * x2 + 1) * tab[k, 0, i] + (x3 - 2 * x2 + x) * h * tab[k, 1, i]
                  + (-2 * x3 + 3 * x2) * tab[k + 1, 0, i] + (x3 - x2) * h * tab[k + 1, 1, i])


@njit(**_INNER)
def _at(t, E, M, sun, moon, axis):
    """Environment.at: integration -> ITRF matrix, Sun, Moon, the Earth's axis at ``t``."""
    cfg, QQ, W, ERA = E[0], E[2], E[3], E[4]
    grid = cfg[_GRID]
    u = (t - cfg[_T0]) / grid
    k = int(min(max(math.floor(u), 0.0), cfg[_NNODES] - 2))
    x = u - k
    # element loops, not array expressions and slice copies: the same arithmetic, and numba
    # compiles far less for them (an array expression or a slice copy adds a compiled loop nest)
    qq, w, r3 = np.empty((3, 3)), np.empty((3, 3)), np.empty((3, 3))
    for i in range(3):
        for j in range(3):
            qq[i, j] = (1 - x) * QQ[k, 3 * i + j] + x * QQ[k + 1, 3 * i + j]
            w[i, j] = (1 - x) * W[k, 3 * i + j] + x * W[k + 1, 3 * i + j]
    era = (1 - x) * ERA[k] + x * ERA[k + 1]
    c, sn = math.cos(era), math.sin(era)
    r3[0, 0], r3[0, 1], r3[0, 2] = c, sn, 0.0
    r3[1, 0], r3[1, 1], r3[1, 2] = -sn, c, 0.0
    r3[2, 0], r3[2, 1], r3[2, 2] = 0.0, 0.0, 1.0
    m = _mat3(_mat3(w, r3), qq)
    for i in range(3):
        for j in range(3):
            M[i, j] = m[i, j]
    _hermite(E[5], k, x, grid, sun)
    _hermite(E[6], k, x, grid, moon)
    axis[0], axis[1], axis[2] = qq[2, 0], qq[2, 1], qq[2, 2]


@njit(**_INNER)
def _point_mass(r, body, gm, acc):
    """M&G eq. 3.37, added to ``acc``."""
    d0, d1, d2 = body[0] - r[0], body[1] - r[1], body[2] - r[2]
    dn = math.sqrt(d0 * d0 + d1 * d1 + d2 * d2)
    sn = math.sqrt(body[0] ** 2 + body[1] ** 2 + body[2] ** 2)
    dn3, sn3 = dn ** 3, sn ** 3
    acc[0] += gm * (d0 / dn3 - body[0] / sn3)
    acc[1] += gm * (d1 / dn3 - body[1] / sn3)
    acc[2] += gm * (d2 / dn3 - body[2] / sn3)


@njit(**_INNER)
def _discs(r, sun, re, axis, flat):
    """Apparent radii of the Sun and the Earth and their separation (srp._discs)."""
    k = 1.0 / (1.0 - flat) - 1.0
    ra = r[0] * axis[0] + r[1] * axis[1] + r[2] * axis[2]
    sa = sun[0] * axis[0] + sun[1] * axis[1] + sun[2] * axis[2]
    rs0, rs1, rs2 = r[0] + k * ra * axis[0], r[1] + k * ra * axis[1], r[2] + k * ra * axis[2]
    d0 = sun[0] + k * sa * axis[0] - rs0
    d1 = sun[1] + k * sa * axis[1] - rs1
    d2 = sun[2] + k * sa * axis[2] - rs2
    rn = math.sqrt(rs0 ** 2 + rs1 ** 2 + rs2 ** 2)
    dn = math.sqrt(d0 ** 2 + d1 ** 2 + d2 ** 2)
    a = math.asin(min(max(_R_SUN / dn, -1.0), 1.0))
    b = math.asin(min(max(re / rn, -1.0), 1.0))
    c = math.acos(min(max(-(rs0 * d0 + rs1 * d1 + rs2 * d2) / (rn * dn), -1.0), 1.0))
    return a, b, c


@njit(**_INNER)
def _shadow(r, sun, re, axis, flat):
    """Visible fraction of the solar disc (M&G eqs. 3.79-3.86, the stretched oblate Earth)."""
    a, b, c = _discs(r, sun, re, axis, flat)
    if c <= b - a:
        return 0.0
    if abs(a - b) < c and c < a + b:
        x = (c * c + a * a - b * b) / (2 * c)
        y = math.sqrt(max(a * a - x * x, 0.0))
        area = (a * a * math.acos(min(max(x / a, -1.0), 1.0)) + b * b * math.acos(min(max((c - x) / b, -1.0), 1.0))
                - c * y)
        return 1.0 - area / (math.pi * a * a)
    if c < a - b:
        return 1.0 - (b / a) ** 2
    return 1.0


@njit(**_INNER)
def _signs(t, r, E):
    """Environment.shadow_signs: outside the penumbra, outside the umbra."""
    cfg = E[0]
    M = np.empty((3, 3))
    sun, moon, axis = np.empty(3), np.empty(3), np.empty(3)
    _at(t, E, M, sun, moon, axis)
    a, b, c = _discs(r[:3], sun, cfg[_RE], axis, cfg[_FLAT])
    return c - (a + b) >= 0.0, c - (b - a) >= 0.0


@njit(**_INNER)
def _interp(F, y_old, x, k):
    """scipy's Dop853DenseOutput at the fraction ``x`` of the step: the first ``k`` components."""
    out = np.zeros(k)
    nf = F.shape[0]
    for i in range(nf):
        for j in range(k):
            out[j] += F[nf - 1 - i, j]
            out[j] *= x if i % 2 == 0 else (1 - x)
    for j in range(k):
        out[j] += y_old[j]
    return out


@njit
def _height(r):
    """Geodetic height (m) on WGS-84 (ERFA gc2gde, Fukushima's method)."""
    a, f = WGS84_A, WGS84_F
    aeps2 = a * a * 1e-32
    e2 = (2.0 - f) * f
    e4t = e2 * e2 * 1.5
    ec2 = 1.0 - e2
    ec = math.sqrt(ec2)
    x, y, z = r[0], r[1], r[2]
    p2 = x * x + y * y
    absz = abs(z)
    if p2 > aeps2:
        p = math.sqrt(p2)
        s0 = absz / a
        pn = p / a
        zc = ec * s0
        c0 = ec * pn
        c02 = c0 * c0
        c03 = c02 * c0
        s02 = s0 * s0
        s03 = s02 * s0
        a02 = c02 + s02
        a0 = math.sqrt(a02)
        a03 = a02 * a0
        d0 = zc * a03 + e2 * s03
        f0 = pn * a03 - e2 * c03
        b0 = e4t * s02 * c02 * pn * (a0 - ec)
        s1 = d0 * f0 - b0 * s0
        cc = ec * (f0 * f0 - b0 * c0)
        s12 = s1 * s1
        cc2 = cc * cc
        return (p * cc + absz * s1 - a * math.sqrt(ec2 * s12 + cc2)) / math.sqrt(s12 + cc2)
    return absz - a * ec


@njit
def _interp2(x, xp, f1, f2):
    """``(np.interp(x, xp, f1), np.interp(x, xp, f2))`` for a scalar ``x`` and increasing ``xp`` with
    one search of the interval and no arrays: numba's np.interp arithmetic (a copy of numpy's
    ``arr_interp``: the slope computed at the interval, the node's value at a node and at the
    end, the value from the other end when one gives NaN), so the same numbers."""
    n = xp.size
    if x != x:
        return x, x
    if x < xp[0]:
        return f1[0], f2[0]
    if x > xp[n - 1]:
        return f1[n - 1], f2[n - 1]
    lo, hi = 0, n - 1                        # xp[lo] <= x; the last j with xp[j] <= x
    while hi - lo > 1:
        mid = (lo + hi) // 2
        if x >= xp[mid]:
            lo = mid
        else:
            hi = mid
    j = n - 1 if x >= xp[n - 1] else lo
    if j == n - 1 or xp[j] == x:
        return f1[j], f2[j]
    return _lerp(x, xp, f1, j), _lerp(x, xp, f2, j)


@njit
def _lerp(x, xp, fp, j):
    """numba's (numpy's) np.interp inside the interval ``j``: the slope, the value from the left
    node, from the right one when that is NaN."""
    slope = (fp[j + 1] - fp[j]) / (xp[j + 1] - xp[j])
    v = slope * (x - xp[j]) + fp[j]
    if math.isnan(v):
        v = slope * (x - xp[j + 1]) + fp[j + 1]
        if math.isnan(v) and fp[j] == fp[j + 1]:
            v = fp[j]
    return v


@njit(**_INNER)
def _harris_priester(h, r_itrf, sun_itrf, n):
    """Density (kg/m³), M&G eqs. 3.99-3.104 as drag.harris_priester."""
    if h > _HP_H[-1]:
        return 0.0
    hc = min(max(h, _HP_H[0]), _HP_H[-1])
    lmin, lmax = _interp2(hc, _HP_H, _HP_LMIN, _HP_LMAX)
    rho_min = math.exp(lmin)
    rho_max = math.exp(lmax)
    sn = math.sqrt(sun_itrf[0] ** 2 + sun_itrf[1] ** 2 + sun_itrf[2] ** 2)
    s0, s1, s2 = sun_itrf[0] / sn, sun_itrf[1] / sn, sun_itrf[2] / sn
    c, si = math.cos(_LAG), math.sin(_LAG)
    ax, ay, az = c * s0 - si * s1, si * s0 + c * s1, s2
    rn = math.sqrt(r_itrf[0] ** 2 + r_itrf[1] ** 2 + r_itrf[2] ** 2)
    cos_psi = (r_itrf[0] * ax + r_itrf[1] * ay + r_itrf[2] * az) / rn
    cos2 = min(max(0.5 * (1.0 + cos_psi), 0.0), 1.0)
    return rho_min + (rho_max - rho_min) * cos2 ** (n / 2.0)


@njit(**_INNER)
def _position_part(t, r, F, central, cfg, M, sun, moon, out):
    """Field (in ITRF through M) + Sun + Moon at inertial ``r`` into ``out``."""
    r_itrf = _mv(M, r)
    fi = np.empty(3)
    _field_acc(r_itrf, F, central, fi)
    for i in range(3):
        out[i] = fi[0] * M[0, i] + fi[1] * M[1, i] + fi[2] * M[2, i]
    if cfg[_SUN]:
        _point_mass(r, sun, _GM_SUN, out)
    if cfg[_MOON]:
        _point_mass(r, moon, _GM_MOON, out)


@njit(**_INNER)
def _density(r, M, sun_itrf, n):
    """Harris-Priester density (kg/m³) at inertial ``r``; ``sun_itrf`` the Sun in ITRF."""
    r_itrf = (M[0, 0] * r[0] + M[0, 1] * r[1] + M[0, 2] * r[2], M[1, 0] * r[0] + M[1, 1] * r[1] + M[1, 2] * r[2],
              M[2, 0] * r[0] + M[2, 1] * r[1] + M[2, 2] * r[2])             # _mv's sums, without its array
    return _harris_priester(_height(r_itrf), r_itrf, sun_itrf, n)


@njit(**_INNER)
def _rest(t, r, v, E, M, sun, axis, acc, unit, with_units):
    """Relativity, SRP, drag and the empirical accelerations added to ``acc`` (the position
    part); ``unit`` (11, 3) gets the unit-coefficient parts in PARAMETERS order."""
    cfg = E[0]
    rho = _density(r, M, _mv(M, sun), cfg[_HPN]) if cfg[_DRAG] else 0.0
    _rest_rho(t, r, v, cfg, E[1], sun, axis, acc, unit, with_units, rho)


@njit(**_INNER)
def _rest_rho(t, r, v, cfg, q, sun, axis, acc, unit, with_units, rho):
    """:func:`_rest` with the density ``rho`` at ``r`` given: it depends on the position alone,
    so the velocity differences of :func:`_partials` reuse it (the same number). Scalars, not
    small arrays, and the settings ``cfg`` and the empirical frame ``q``, not the tuple of every
    table (numba counts the references of each array a call passes): this runs 13 times per
    right-hand side with the variational equations. Callers pass ``with_units`` as ``bool(...)``:
    a bare ``True`` or ``False`` is a literal type to numba, which would compile this twice."""
    if cfg[_REL]:
        gm = cfg[_GM]
        rn = math.sqrt(r[0] ** 2 + r[1] ** 2 + r[2] ** 2)
        v2 = v[0] * v[0] + v[1] * v[1] + v[2] * v[2]
        rv = r[0] * v[0] + r[1] * v[1] + r[2] * v[2]
        f = gm / (C_LIGHT ** 2 * rn ** 3)
        for i in range(3):
            acc[i] += f * ((4 * gm / rn - v2) * r[i] + 4 * rv * v[i])
    if cfg[_SRP]:
        d = (r[0] - sun[0], r[1] - sun[1], r[2] - sun[2])
        dn = math.sqrt(d[0] ** 2 + d[1] ** 2 + d[2] ** 2)
        nu = _shadow(r, sun, cfg[_RE], axis, cfg[_FLAT])
        for i in range(3):
            a1 = nu * 1.0 * _P_SUN * (_AU / dn) ** 2 * cfg[_AM_SRP] * d[i] / dn
            acc[i] += cfg[_CR] * a1
            unit[0, i] = a1
    if cfg[_DRAG]:
        cx = axis[1] * r[2] - axis[2] * r[1]
        cy = axis[2] * r[0] - axis[0] * r[2]
        cz = axis[0] * r[1] - axis[1] * r[0]
        vr0, vr1, vr2 = v[0] - OMEGA_EARTH * cx, v[1] - OMEGA_EARTH * cy, v[2] - OMEGA_EARTH * cz
        vn = math.sqrt(vr0 ** 2 + vr1 ** 2 + vr2 ** 2)
        f = -0.5 * rho * 1.0 * cfg[_AM_DRAG] * vn
        a0, a1, a2 = f * vr0, f * vr1, f * vr2
        acc[0] += cfg[_CD] * a0
        acc[1] += cfg[_CD] * a1
        acc[2] += cfg[_CD] * a2
        unit[1, 0], unit[1, 1], unit[1, 2] = a0, a1, a2
    er, et, en = cfg[_ER], cfg[_ER + 1], cfg[_ER + 2]
    emp = er != 0.0 or et != 0.0 or en != 0.0
    if emp or with_units:
        rn = math.sqrt(r[0] ** 2 + r[1] ** 2 + r[2] ** 2)
        r0, r1, r2 = r[0] / rn, r[1] / rn, r[2] / rn
        h0, h1, h2 = r[1] * v[2] - r[2] * v[1], r[2] * v[0] - r[0] * v[2], r[0] * v[1] - r[1] * v[0]
        hn = math.sqrt(h0 ** 2 + h1 ** 2 + h2 ** 2)
        n0, n1, n2 = h0 / hn, h1 / hn, h2 / hn
        t0, t1, t2 = n1 * r2 - n2 * r1, n2 * r0 - n0 * r2, n0 * r1 - n1 * r0
        if emp:
            acc[0] += er * r0 + et * t0 + en * n0
            acc[1] += er * r1 + et * t1 + en * n1
            acc[2] += er * r2 + et * t2 + en * n2
        unit[2, 0], unit[3, 0], unit[4, 0] = r0, t0, n0
        unit[2, 1], unit[3, 1], unit[4, 1] = r1, t1, n1
        unit[2, 2], unit[3, 2], unit[4, 2] = r2, t2, n2
    x0, x1, x2 = cfg[_EX] + t * cfg[_EXR], cfg[_EX + 1] + t * cfg[_EXR + 1], cfg[_EX + 2] + t * cfg[_EXR + 2]
    if x0 != 0.0 or x1 != 0.0 or x2 != 0.0:
        for i in range(3):
            acc[i] += q[i, 0] * x0 + q[i, 1] * x1 + q[i, 2] * x2
    if with_units:
        for j in range(3):
            for i in range(3):
                unit[5 + j, i] = q[i, j]
                unit[8 + j, i] = t * q[i, j]


@njit
def _acceleration(t, r, v, E, F, acc):
    """Total acceleration (central + perturbation) at one state into ``acc``."""
    M = np.empty((3, 3))
    sun, moon, axis = np.empty(3), np.empty(3), np.empty(3)
    _at(t, E, M, sun, moon, axis)
    unit = np.zeros((11, 3))
    _position_part(t, r, F, False, E[0], M, sun, moon, acc)
    _rest(t, r, v, E, M, sun, axis, acc, unit, bool(False))
    gm = E[0][_GM]
    rn = math.sqrt(r[0] ** 2 + r[1] ** 2 + r[2] ** 2)
    for i in range(3):
        acc[i] = -gm * r[i] / rn ** 3 + acc[i]


@njit
def _partials(t, r, v, E, F, HT, a, g, hv, dp, work):
    """Environment.partials with the field's and the Sun's and Moon's ``∂a/∂r`` analytic (the
    field's from ``HT``, hessian_tables of the STM's field), the rest (relativity, SRP, drag,
    empirical) by the same central differences (1 m, 1 mm/s), the central term analytic;
    ``∂a/∂v`` and ``∂a/∂p`` as there. ``work`` (:data:`_NWORK`,) holds the intermediate arrays:
    this runs at every stage of every step, and allocating them each time cost more than their
    arithmetic."""
    cfg, q, codes = E[0], E[1], E[7]
    M = work[0:9].reshape((3, 3))
    sun, moon, axis = work[9:12], work[12:15], work[15:18]
    _at(t, E, M, sun, moon, axis)
    unit = work[18:51].reshape((11, 3))
    unit[:, :] = 0.0
    scratch = work[51:84].reshape((11, 3))                 # written by the differences, never read
    p0 = work[84:87]
    _position_part(t, r, F, False, E[0], M, sun, moon, p0)
    # the density at r serves the velocity differences below too (it depends on the position alone)
    drag = cfg[_DRAG] != 0.0
    sun_itrf = _mv(M, sun)
    rho = _density(r, M, sun_itrf, cfg[_HPN]) if drag else 0.0
    _rest_rho(t, r, v, cfg, q, sun, axis, p0, unit, bool(True), rho)
    gi = work[87:96].reshape((3, 3))
    _field_hessian(_mv(M, r), HT, gi)
    gf = _mat3(_mat3(M.T.copy(), gi), M)                    # ITRF -> integration frame
    for i in range(3):
        for j in range(3):
            g[i, j] = gf[i, j]
    if cfg[_SUN]:
        _point_mass_gradient(r, sun, _GM_SUN, g)
    if cfg[_MOON]:
        _point_mass_gradient(r, moon, _GM_MOON, g)
    hr, hvs = 1.0, 1e-3
    pp, pm = work[96:99], work[99:102]
    # the differences need the accelerations only, not the unit parts (with_units False)
    rr = work[102:105]
    for i in range(3):
        rr[i] = r[i]
    for j in range(3):
        rr[j] = r[j] + hr
        pp[:] = 0.0
        rho_d = _density(rr, M, sun_itrf, cfg[_HPN]) if drag else 0.0
        _rest_rho(t, rr, v, cfg, q, sun, axis, pp, scratch, bool(False), rho_d)
        rr[j] = r[j] - hr
        pm[:] = 0.0
        rho_d = _density(rr, M, sun_itrf, cfg[_HPN]) if drag else 0.0
        _rest_rho(t, rr, v, cfg, q, sun, axis, pm, scratch, bool(False), rho_d)
        rr[j] = r[j]
        for i in range(3):
            g[i, j] += (pp[i] - pm[i]) / (2 * hr)
    vv = work[105:108]
    for i in range(3):
        vv[i] = v[i]
    for j in range(3):
        vv[j] = v[j] + hvs
        pp[:] = 0.0
        _rest_rho(t, r, vv, cfg, q, sun, axis, pp, scratch, bool(False), rho)
        vv[j] = v[j] - hvs
        pm[:] = 0.0
        _rest_rho(t, r, vv, cfg, q, sun, axis, pm, scratch, bool(False), rho)
        vv[j] = v[j]
        for i in range(3):
            hv[i, j] = (pp[i] - pm[i]) / (2 * hvs)
    gm = cfg[_GM]
    rn = math.sqrt(r[0] ** 2 + r[1] ** 2 + r[2] ** 2)
    for i in range(3):
        for j in range(3):
            g[i, j] = g[i, j] + gm * (3.0 * r[i] * r[j] / rn ** 5 - (1.0 if i == j else 0.0) / rn ** 3)
        a[i] = p0[i] - gm * r[i] / rn ** 3
    for k in range(codes.size):
        for i in range(3):
            dp[i, k] = unit[codes[k], i]


#: The partials' intermediate arrays in :func:`_work` (:func:`_partials` lays them out), then ∂a/∂p
_NWORK = 129


@njit
def _work(npar):
    """The work array of :func:`_rhs` and :func:`_partials` for ``npar`` parameters."""
    return np.zeros(_NWORK + 3 * max(npar, 1))


@njit(**_INNER)
def _rhs(t, y, stm, npar, E, F, HT, out, work):
    """The state's derivative, with Φ' = A Φ and S' = A S + [0; ∂a/∂p] when ``stm``; ``work``
    (:func:`_work`) the partials' intermediate arrays."""
    out[0], out[1], out[2] = y[3], y[4], y[5]
    if not stm:
        acc = np.empty(3)
        _acceleration(t, y[:3], y[3:6], E, F, acc)
        out[3], out[4], out[5] = acc[0], acc[1], acc[2]
        return
    a, g, hv = work[108:111], work[111:120].reshape((3, 3)), work[120:129].reshape((3, 3))
    dp = work[_NWORK:].reshape((3, max(npar, 1)))
    _partials(t, y[:3], y[3:6], E, F, HT, a, g, hv, dp, work)
    out[3], out[4], out[5] = a[0], a[1], a[2]
    ncol = 6 + npar
    # Φ rows 0..5 at y[6:42] (6 x 6), S at y[42:] (6 x npar): treat [Φ S] column by column
    for c in range(ncol):
        if c < 6:
            base, stride, col = 6, 6, c
        else:
            base, stride, col = 42, npar, c - 6
        for i in range(3):
            out[base + i * stride + col] = y[base + (3 + i) * stride + col]
        for i in range(3):
            s1, s2 = 0.0, 0.0
            for k in range(3):
                s1 += g[i, k] * y[base + k * stride + col]
                s2 += hv[i, k] * y[base + (3 + k) * stride + col]
            s = s1 + s2
            if c >= 6:
                s += dp[i, col]
            out[base + (3 + i) * stride + col] = s


@njit(**_INNER)
def _rms(x):
    s = 0.0
    for i in range(x.size):
        s += x[i] * x[i]
    return math.sqrt(s) / math.sqrt(x.size)


@njit
def integrate(y0, t_end, rtol, atol, max_step, max_steps, stm, npar, E, F, HT):
    """DOP853 from t = 0 to ``t_end`` as scipy's (same tableau, error norm, controller and
    first step). Returns ``(outcome, nfev, t_old (S,), y_old (S, n), dense (S, 7, n), t)``:
    outcome 0 success, 1 step limit, 2 non-finite or too small a step; ``t`` where it stopped.

    One numba kernel on purpose: it follows scipy's DOP853 loop step for step (first step, stages, error
    norm, controller, dense output) so that it can be read against it, and its parts share the step's arrays.
    """
    n = y0.size
    direction = 1.0 if t_end >= 0.0 else -1.0
    t = 0.0
    y = y0.copy()
    f = np.empty(n)
    work = _work(npar)
    _rhs(t, y, stm, npar, E, F, HT, f, work)
    nfev = 1
    # select_initial_step (scipy common.py; Hairer et al. II.4); element loops rather than array
    # expressions and slice copies throughout, the same arithmetic for a fraction of the compile
    interval = abs(t_end)
    scale, q0, q1 = np.empty(n), np.empty(n), np.empty(n)
    for i in range(n):
        scale[i] = atol[i] + abs(y[i]) * rtol[i]
        q0[i] = y[i] / scale[i]
        q1[i] = f[i] / scale[i]
    d0, d1 = _rms(q0), _rms(q1)
    h0 = 1e-6 if (d0 < 1e-5 or d1 < 1e-5) else 0.01 * d0 / d1
    h0 = min(h0, interval)
    f1 = np.empty(n)
    for i in range(n):
        q0[i] = y[i] + h0 * direction * f[i]
    _rhs(t + h0 * direction, q0, stm, npar, E, F, HT, f1, work)
    nfev += 1
    for i in range(n):
        q1[i] = (f1[i] - f[i]) / scale[i]
    d2 = _rms(q1) / h0
    if d1 <= 1e-15 and d2 <= 1e-15:
        h1 = max(1e-6, h0 * 1e-3)
    else:
        h1 = (0.01 / max(d1, d2)) ** (1.0 / 8.0)
    h_abs = min(100 * h0, h1, interval, max_step)
    K = np.empty((16, n))
    cap = 64
    t_olds = np.empty(cap)
    y_olds = np.empty((cap, n))
    dense = np.empty((cap, 7, n))
    steps = 0
    outcome = 0
    err_exp = -1.0 / 8.0
    ynew = np.empty(n)
    fnew = np.empty(n)
    ys = np.empty(n)
    # shadow boundaries end the steps (as integrator.propagate's numpy loop: a redone step, then
    # a restart at the step size from before)
    events = E[0][_SRP] != 0.0
    s1, s2 = False, False
    if events:
        s1, s2 = _signs(0.0, y0, E)
    t_seg = t_end
    resume_h = 0.0
    while True:
        if t == t_end:
            break
        if steps >= max_steps:
            outcome = 1
            break
        min_step = 10 * abs(np.nextafter(t, direction * np.inf) - t)
        if h_abs > max_step:
            h_abs = max_step
        elif h_abs < min_step:
            h_abs = min_step
        accepted = False
        rejected = False
        failed = False
        h = 0.0
        t_new = t
        while not accepted:
            if h_abs < min_step:
                failed = True
                break
            h = h_abs * direction
            t_new = t + h
            if direction * (t_new - t_seg) > 0:
                t_new = t_seg
            h = t_new - t
            h_abs = abs(h)
            for i in range(n):
                K[0, i] = f[i]
            for s in range(1, _NS):
                for i in range(n):
                    acc = 0.0
                    for j in range(s):
                        acc += K[j, i] * _A[s, j]
                    ys[i] = y[i] + acc * h
                _rhs(t + _C[s] * h, ys, stm, npar, E, F, HT, K[s], work)
            for i in range(n):
                acc = 0.0
                for j in range(_NS):
                    acc += K[j, i] * _B[j]
                ynew[i] = y[i] + h * acc
            _rhs(t + h, ynew, stm, npar, E, F, HT, fnew, work)
            nfev += _NS
            for i in range(n):
                K[_NS, i] = fnew[i]
            e5, e3 = 0.0, 0.0
            for i in range(n):
                sc = atol[i] + max(abs(y[i]), abs(ynew[i])) * rtol[i]
                s5, s3 = 0.0, 0.0
                for j in range(_NS + 1):
                    s5 += K[j, i] * _E5[j]
                    s3 += K[j, i] * _E3[j]
                s5 /= sc
                s3 /= sc
                e5 += s5 * s5
                e3 += s3 * s3
            if e5 == 0.0 and e3 == 0.0:
                err = 0.0
            else:
                err = abs(h) * e5 / math.sqrt((e5 + 0.01 * e3) * n)
            if err < 1:
                if err == 0:
                    factor = _MAX_FACTOR
                else:
                    factor = min(_MAX_FACTOR, _SAFETY * err ** err_exp)
                if rejected:
                    factor = min(1.0, factor)
                h_abs *= factor
                accepted = True
            else:
                h_abs *= max(_MIN_FACTOR, _SAFETY * err ** err_exp)
                rejected = True
        if failed:
            outcome = 2
            break
        finite = True
        for i in range(n):
            if not math.isfinite(ynew[i]):
                finite = False
        if not finite:
            outcome = 2
            break
        if steps == cap:
            cap *= 2
            t2 = np.empty(cap)
            y2 = np.empty((cap, n))
            d2_ = np.empty((cap, 7, n))
            for s in range(steps):
                t2[s] = t_olds[s]
                for i in range(n):
                    y2[s, i] = y_olds[s, i]
                    for j in range(7):
                        d2_[s, j, i] = dense[s, j, i]
            t_olds, y_olds, dense = t2, y2, d2_
        # dense output: three extra stages and the interpolant's coefficients (scipy's F)
        for s in range(_NS + 1, 16):
            for i in range(n):
                acc = 0.0
                for j in range(s):
                    acc += K[j, i] * _A[s, j]
                ys[i] = y[i] + acc * h
            _rhs(t + _C[s] * h, ys, stm, npar, E, F, HT, K[s], work)
        nfev += 3
        for i in range(n):
            dy = ynew[i] - y[i]
            dense[steps, 0, i] = dy
            dense[steps, 1, i] = h * K[0, i] - dy
            dense[steps, 2, i] = 2 * dy - h * (fnew[i] + K[0, i])
            for r in range(4):
                acc = 0.0
                for j in range(16):
                    acc += _D[r, j] * K[j, i]
                dense[steps, 3 + r, i] = h * acc
        if events:
            n1, n2 = _signs(t_new, ynew, E)
            if (n1 != s1 or n2 != s2) and t_new != t_seg:
                lo, hi = t, t_new
                while abs(hi - lo) > 1e-9:
                    mid = 0.5 * (lo + hi)
                    p = _interp(dense[steps], y, (mid - t) / h, 3)
                    m1, m2 = _signs(mid, p, E)
                    if m1 != s1 or m2 != s2:
                        hi = mid
                    else:
                        lo = mid
                t_next = hi + _EVENT_PAST_S * direction
                if direction * (t_next - t_end) > 0:
                    t_next = t_end
                if direction * (t_next - t_new) < 0:     # else a redo would repeat this step
                    t_seg = t_next
                    resume_h = abs(h)
                    h_abs = abs(t_seg - t)
                    continue
            s1, s2 = n1, n2
        t_olds[steps] = t
        for i in range(n):
            y_olds[steps, i] = y[i]
        steps += 1
        t = t_new
        for i in range(n):
            y[i] = ynew[i]
            f[i] = fnew[i]
        if direction * (t - t_end) >= 0:
            break
        if t_seg != t_end and direction * (t - t_seg) >= 0:
            t_seg = t_end
            h_abs = min(resume_h, abs(t_end - t))
    return outcome, nfev, t_olds[:steps].copy(), y_olds[:steps].copy(), dense[:steps].copy(), t


# -- thin wrappers for tests -----------------------------------------------------------------
def perturbation(env, t, r, v):
    """Total acceleration at one state through the compiled kernels (for tests)."""
    E = environment_tables(env)
    F = field_tables(env.model.field)
    acc = np.empty(3)
    with compile_once([_acceleration], "force"):        # integrate's lock: one process compiles
        _acceleration(float(t), np.asarray(r, float), np.asarray(v, float), E, F, acc)
    return acc


def partials(env, t, r, v):
    """``(a, ∂a/∂r, ∂a/∂v, ∂a/∂p)`` through the compiled kernels (for tests)."""
    est = tuple(env.model.estimated)
    E = environment_tables(env, est)
    F = field_tables(env.model.field)
    HT = hessian_tables(stm_field(env))
    a, g, hv = np.empty(3), np.empty((3, 3)), np.empty((3, 3))
    dp = np.zeros((3, max(len(est), 1)))
    with compile_once([_partials], "force"):
        _partials(float(t), np.asarray(r, float), np.asarray(v, float), E, F, HT, a, g, hv, dp, _work(len(est)))
    return a, g, hv, dp[:, :len(est)]

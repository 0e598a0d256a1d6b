"""The tables the compiled full force model reads (:mod:`trackproc.dynamics.forces.compiled`), built
in numpy: the field's recursion and summation tables, its second-derivative weights, the
environment's settings and tabulated Earth rotation, Sun and Moon.

A module of its own so that a process running the kernels from their stored machine code
(:mod:`trackproc.dynamics.forces.native`) builds the kernels' arguments without importing numba.
"""

from __future__ import annotations

import math
from fractions import Fraction

import numpy as np

from trackproc.constants import WGS84_F
from trackproc.dynamics.forces.model import GRID_S, PARAMETERS

__all__ = ["supported", "field_tables", "stm_field", "hessian_tables", "environment_tables"]

# cfg slots of environment_tables
(_GM, _T0, _GRID, _NNODES, _SUN, _MOON, _REL, _SRP, _DRAG, _AM_SRP, _CR, _AM_DRAG, _CD, _RE, _FLAT,
 _HPN, _ER, _EX, _EXR, _NCFG) = (0, 1, 2, 3, 4, 5, 6, 7, 8, 9, 10, 11, 12, 13, 14, 15, 16, 19, 22, 25)


def supported(model) -> bool:
    """Whether :func:`integrate` covers the model (everything but the NRLMSIS atmosphere)."""
    return not (model.drag and model.atmosphere != "harris-priester")


def field_tables(field):
    """The field's recursion and summation tables as a tuple of arrays for the kernels."""
    t = field._coefficient_tables()
    dims = np.array([field.degree + 1, min(field.order + 1, field.degree + 1)], np.int64)
    consts = np.array([field.gm_m3_s2, field.radius_m])
    return (np.ascontiguousarray(t["a"]), np.ascontiguousarray(t["b"]), np.ascontiguousarray(t["fprod"]),
            np.ascontiguousarray(t["p1"]), np.ascontiguousarray(t["p2"]), np.ascontiguousarray(t["p3"]),
            t["n"].astype(np.int64), t["m"].astype(np.int64), dims, consts)


def _normalisation(n: int, m: int) -> float:
    """``N_nm = sqrt((n+m)! / ((2-δ_m0)(2n+1)(n-m)!))``: ``V_nm = N_nm V̄_nm`` (gravity_field's convention)."""
    return math.sqrt(Fraction(math.factorial(n + m), math.factorial(n - m) * (1 if m == 0 else 2) * (2 * n + 1)))


def _derivative(w: dict, axis: int) -> dict:
    """``∂/∂x_axis`` (times R) of ``Re Σ w_nm Z_nm`` (unnormalised ``Z = V + iW``) as the same form
    one degree up: M&G eq. 3.33 read for C = 1, S = 0 and C = 0, S = 1::

        R ∂Z_nm/∂x = ½ (-Z_n+1,m+1 + (n-m+2)(n-m+1) Z_n+1,m-1),   m = 0: -Re Z_n+1,1
        R ∂Z_nm/∂y = ½ i (Z_n+1,m+1 + (n-m+2)(n-m+1) Z_n+1,m-1),  m = 0: -Im Z_n+1,1
        R ∂Z_nm/∂z = -(n-m+1) Z_n+1,m
    """
    out: dict = {}

    def add(key, value):
        out[key] = out.get(key, 0.0) + value

    for (n, m), q in w.items():
        k = (n - m + 2) * (n - m + 1)
        if axis == 2:
            add((n + 1, m), -(n - m + 1) * q)
        elif m == 0:                       # Z_n0 is real: only Re q counts
            add((n + 1, 1), -q.real if axis == 0 else 1j * q.real)
        elif axis == 0:
            add((n + 1, m + 1), -0.5 * q)
            add((n + 1, m - 1), 0.5 * k * q)
        else:
            add((n + 1, m + 1), 0.5j * q)
            add((n + 1, m - 1), 0.5j * k * q)
    return out


#: hessian_tables' results by the field's content (insertion order: the oldest leaves first)
_HESSIANS: dict = {}


def stm_field(env):
    """The field of the STM's gradient (Environment._stm_field: cut to ForceModel.stm_degree)."""
    low = env._stm_field()
    return low if low is not None else env.model.field


def hessian_tables(field):
    """The field's second derivatives as weights of the normalised solid harmonics to degree
    N+2: ``∂²U/∂x_i∂x_j = GM/R³ Re Σ H_ij,nm Z̄_nm`` (the six of xx, xy, xz, yy, yz, zz; the
    central term left out), with the recursion tables to that degree (two applications of
    :func:`_derivative` to ``w = (C̄ - i S̄) / N``)."""
    # by content: each Environment cuts its own copy of the STM's field, and the exact rational
    # normalisations below cost ~0.1 s for a 20x20 field, more than a filter segment's integration
    key = (field.degree, field.order, field.gm_m3_s2, field.radius_m, np.asarray(field.cbar).tobytes(),
           np.asarray(field.sbar).tobytes())
    if key in _HESSIANS:
        return _HESSIANS[key]
    deg, order = field.degree, field.order
    nmax, mmax = deg + 2, min(order + 2, deg + 2)
    w = {(n, m): complex(field.cbar[n, m], -field.sbar[n, m]) / _normalisation(n, m)
         for n in range(1, deg + 1) for m in range(min(n, order) + 1)
         if field.cbar[n, m] != 0.0 or field.sbar[n, m] != 0.0}
    first = [_derivative(w, i) for i in range(3)]
    H = np.zeros((6, nmax + 1, nmax + 1), np.complex128)
    for k, (i, j) in enumerate(((0, 0), (0, 1), (0, 2), (1, 1), (1, 2), (2, 2))):
        for (n, m), q in _derivative(first[j], i).items():
            H[k, n, m] += q * _normalisation(n, m)
    a = np.zeros((nmax + 1, nmax + 1))
    b = np.zeros((nmax + 1, nmax + 1))
    for n in range(1, nmax + 1):
        for m in range(min(n, mmax + 1)):
            a[n, m] = math.sqrt((2 * n - 1) * (2 * n + 1) / ((n - m) * (n + m)))
            if n - m >= 2:
                b[n, m] = math.sqrt((n + m - 1) * (n - m - 1) * (2 * n + 1) / ((n + m) * (n - m) * (2 * n - 3)))
    f = np.array([1.0, math.sqrt(3.0)] + [math.sqrt((2 * m + 1) / (2 * m)) for m in range(2, nmax + 1)])[:nmax + 1]
    dims = np.array([nmax, mmax], np.int64)
    out = (H, a, b, np.cumprod(f), dims, np.array([field.gm_m3_s2, field.radius_m]))
    if len(_HESSIANS) >= 8:                                   # a few fields per process at most
        _HESSIANS.pop(next(iter(_HESSIANS)))
    _HESSIANS[key] = out
    return out


def environment_tables(env, estimated=()):
    """An :class:`~trackproc.dynamics.forces.model.Environment` as a tuple of arrays: settings,
    the integration frame, the tabulated Earth rotation, Sun and Moon, the estimated parameters'
    codes (their index in :data:`~trackproc.dynamics.forces.model.PARAMETERS`)."""
    mdl = env.model
    sc = mdl.spacecraft
    cfg = np.zeros(_NCFG)
    cfg[_GM] = mdl.field.gm_m3_s2
    cfg[_T0], cfg[_GRID], cfg[_NNODES] = env.t0_grid, GRID_S, env.n_nodes
    cfg[_SUN] = "sun" in mdl.third_bodies
    cfg[_MOON] = "moon" in mdl.third_bodies
    cfg[_REL] = bool(mdl.relativity)
    cfg[_SRP] = bool(mdl.srp)
    cfg[_DRAG] = bool(mdl.drag)
    if mdl.srp:
        cfg[_AM_SRP], cfg[_CR] = sc.srp_area_m2 / sc.mass_kg, sc.cr
    if mdl.drag:
        cfg[_AM_DRAG], cfg[_CD] = sc.drag_area_m2 / sc.mass_kg, sc.cd
    cfg[_RE], cfg[_FLAT], cfg[_HPN] = mdl.earth_radius_m, WGS84_F, mdl.hp_exponent
    cfg[_ER:_ER + 3] = mdl.empirical_rtn
    cfg[_EX:_EX + 3] = mdl.empirical_gcrf
    cfg[_EXR:_EXR + 3] = mdl.empirical_gcrf_rate
    codes = np.array([PARAMETERS.index(p) for p in estimated], np.int64)
    return (cfg, np.ascontiguousarray(env.q, float), np.ascontiguousarray(env._qq), np.ascontiguousarray(env._w),
            np.ascontiguousarray(env._era), np.ascontiguousarray(env._sun), np.ascontiguousarray(env._moon), codes)

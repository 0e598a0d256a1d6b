"""Estimation measurement models: values with analytic partials, and bias modifiers.

The estimator's view of the one measurement physics: the light time is
:mod:`trackproc.models.light_time` and the observables with their partials are
:mod:`trackproc.models.observables` (both shared with the simulator,
:mod:`trackproc.models.measurements`); this module adds what only estimation needs — the
total derivatives through the light time with respect to the initial state (eqs. 6, 11-12),
the bias modifiers, and :func:`evaluate`, which models a whole :class:`MeasurementSet`. All
vectors in GCRF (m, m/s, s), every sample time-tagged at **reception** ``t_r`` on the ground.

Geometry (one-way, down leg). The signal received at ``t_r`` left the satellite at
``t_e = t_r - ρ/c``, with ``ρ = |r(t_e) - r_st(t_r)|`` and ``û = (r(t_e) - r_st(t_r)) / ρ``:

    range              ρ (+ range_bias:STATION)                                      (1)
    range-rate         doppler:       ρ̇ = û·(v(t_e) - v_st(t_r)) / (1 + û·v(t_e)/c)   (2)
                       instantaneous: ρ̇ = û·(v(t_e) - v_st(t_r))                       (3)
    Doppler            Δf = -f ρ̇ / c (+ doppler_offset + doppler_drift (t_r - t0))      (4)
    azimuth/elevation  of r(t_e) - r_st(t_r) in the station's ENU frame at t_r       (5)

(seed 002 eq. 17 writes (2) and (1) without light time and without station velocity; the
station's rotation with the Earth is kept here: ``v_st`` is its GCRF velocity.)

Partials with respect to the satellite state at emission, ``s_e = (r(t_e), v(t_e))``, at fixed
``t_e`` (:func:`range_partials`, :func:`range_rate_partials`, :func:`azel_partials`), with
``P = I - ûûᵀ``:

    ∂ρ/∂r_e = ûᵀ
    ∂ρ̇/∂r_e = (v_e - v_st)ᵀ P / (ρ d) - ρ̇ v_eᵀ P / (ρ c d),   ∂ρ̇/∂v_e = ûᵀ (1 - ρ̇/c) / d
             with d = 1 + û·v_e/c (doppler), d = 1 and the ρ̇/c terms dropped (instantaneous)
    ∂(az, el)/∂r_e = ∂(az, el)/∂enu · E · M      (E: ITRF -> ENU, M: GCRF -> ITRF at t_r)

**Through the light time.** ``t_e`` itself depends on the parameters ``p`` (the initial state):
a change ``δp`` moves the satellite by ``Φ(t_e) δp`` at fixed ``t_e`` and the emission time by
``δt_e = -δρ/c``, so ``δρ = û·(Φ_r δp + v_e δt_e)`` gives

    dρ/dp = û·Φ_r(t_e) / (1 + û·v_e/c),    dt_e/dp = -(dρ/dp) / c                     (6)

and the total derivative of the emission state is ``D = Φ(t_e) + ṡ(t_e) (dt_e/dp)`` with
``ṡ = (v, a)`` the state's time derivative (:func:`emission_jacobian`). Every observable
``g(s_e)`` then has ``dg/dp = (∂g/∂s_e) D`` — exact to first order, and the reason the range
partial carries the factor ``1/(1 + û·v/c)``. The station is a known function of ``t_r``
and contributes nothing.

**Two-way** (samples with ``mode`` ``"two-way"``: round trip, the same station transmits and
receives, transponder turnaround ratio 1; the simulator's model). The down leg above ends the
trip: the satellite bounced the signal at ``t_b = t_e``, state ``s_b = (r_b, v_b)``. The up leg
left the station at ``t_t = t_b - ρ_u/c``; with ``T = τ_d + τ_u`` the round-trip light time the
station is moved back from ``t_r`` with its GCRF velocity and centripetal acceleration ``a_st``:

    R(T) = r_st - v_st T + a_st T²/2,   V(T) = v_st - a_st T
    ρ_u = |r_b - R(T)| = c τ_u,   û_u = (r_b - R(T)) / ρ_u                          (7)
    range              (ρ_d + ρ_u)/2  (= c T/2)                                     (8)
    range-rate         (ρ̇_d + ρ̇_u)/2 with ρ̇_d by (2) or (3) and                    (9)
                       doppler:       ρ̇_u = (1 - ρ̇_d/c) û_u·(v_b - V) / (1 - û_u·V/c)
                       instantaneous: ρ̇_u = û_u·(v_b - V)
    Doppler            Δf = -2 f (range-rate) / c  (+ modifiers)                     (10)

(``ρ̇_u`` of (9) is dρ_u/dt_r: the up leg's ends move with ``dt_b/dt_r = 1 - ρ̇_d/c`` and
``dt_t/dt_r = dt_b/dt_r - ρ̇_u/c``.) Azimuth and elevation stay those of the down leg (5).

*Partials through both light times.* A two-way value ``g(s_b, T)`` depends on the bounce state
and, through the station's motion, on ``T``. A change ``δp`` moves the bounce state by ``D δp``
(eq. 6 at ``t_b``, ``D_r`` its position rows) and the round trip by ``δT = (δρ_d + δρ_u)/c``
with ``δρ_d = û_d·D_r δp`` (that is dρ/dp of eq. 6: the bounce-time term of ``D`` supplies the
factor ``1/(1 + û_d·v_b/c)``) and ``δρ_u = û_u·(D_r δp - δR) = û_u·D_r δp + (û_u·V) δT``, so

    dT/dp = (û_d + û_u)·D_r / (c - û_u·V)                                           (11)
    dg/dp = (∂g/∂s_b) D + (∂g/∂T) dT/dp,    ∂R/∂T = -V,  ∂V/∂T = -a_st               (12)

(:func:`round_trip_jacobian`). Range: ``∂/∂r_b = (û_d + û_u)/2``, ``∂/∂T = û_u·V/2``, which
sum to ``(c/2) dT/dp``. Up-leg rate (:func:`up_rate_partials`), with ``e = û_u·V``,
``w = û_u·(v_b - V)``, ``k = (1 - ρ̇_d/c)/(1 - e/c)`` and ``P_u = I - û_u û_uᵀ``:

    ∂ρ̇_u/∂r_b = P_u (k (v_b - V) + ρ̇_u V/(c - e)) / ρ_u,    ∂ρ̇_u/∂v_b = k û_u
    ∂ρ̇_u/∂V = (ρ̇_u/(c - e) - k) û_u,   ∂ρ̇_u/∂R = -∂ρ̇_u/∂r_b,   ∂ρ̇_u/∂ρ̇_d = -w/(c - e)
    ∂ρ̇_u/∂T = (∂ρ̇_u/∂r_b)·V - (∂ρ̇_u/∂V)·a_st                                      (13)

(instantaneous: ``k = 1`` and the ``e`` and ``ρ̇_d`` terms vanish), and the two-way rate
(:func:`two_way_range_rate_partials`) has ``∂/∂s_b = (∂ρ̇_d/∂s_b (1 + ∂ρ̇_u/∂ρ̇_d) + ∂ρ̇_u/∂s_b)/2``
(``∂ρ̇_d/∂s_b`` by :func:`range_rate_partials` with the station at ``t_r``) and
``∂/∂T = (∂ρ̇_u/∂T)/2``. The ``∂/∂T`` terms are small (relative size ~``|V|/c``: ≤ 1.5e-6,
~1e-7 typically in LEO) but above the finite-difference check's resolution (~4e-9), so they
are kept: the partials are exact to first order.

Biases are *modifiers* that own their drivers (:mod:`trackproc.models.modifiers`): each adds
``coefficient × value`` to some rows, so its partial is the coefficient — 1 for a range,
Doppler offset, azimuth or elevation bias, ``t_r - t0`` for a Doppler drift, and
``-c/f`` (``-c (t_r - t0)/f``) when a Doppler offset (drift) acts on range-rate samples that
came from one-way Doppler (``ρ̇ = -c Δf / f``), ``-c/(2f)`` (``-c (t_r - t0)/(2f)``) from
two-way Doppler (``ρ̇ = -c Δf / (2f)``). A range bias of a two-way range is in the range's
(half round trip) metres.

Every partial here is checked against central finite differences in
``tests/models/test_observation.py`` (one-way) and ``tests/cli/test_two_way.py`` (two-way).

One responsibility, the measurement model of a sample set (values and partials through light
time, both legs of a two-way link, angles and the modifiers); a little over 400 lines, most of
them the equations above and their citations.
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import Optional, Sequence

import numpy as np

from trackproc.constants import C_LIGHT, OMEGA_EARTH
from trackproc.models import light_time as lt
from trackproc.models import modifiers as md
from trackproc.models.light_time import LIGHT_TIME_TOL_S, UpLeg, solve_up_leg  # noqa: F401  (re-exported)
from trackproc.models.observables import (azel_partials, azel_value, range_partials,  # noqa: F401  (re-exported)
                                          range_rate_partials, range_rate_value, two_way_range_partials,
                                          two_way_range_rate_partials, up_rate_partials, wrap_pi)
from trackproc.models.observables import check_range_rate_model as _check_model
from trackproc.vocabulary import ESTIMATE_KIND_ORDER, LINK_KINDS, RANGE_RATE_MODELS  # noqa: F401
from trackproc.vocabulary import LINK_MODES as MODES
from trackproc.vocabulary import STATE_NAMES

__all__ = ["KINDS", "RANGE_RATE_MODELS", "MODES", "MeasurementSet", "BiasModifier", "EmissionGeometry", "UpLeg",
           "range_partials", "range_rate_value", "range_rate_partials", "azel_value", "azel_partials",
           "solve_light_time", "emission_jacobian", "evaluate", "bias_modifiers", "wrap_pi",
           "solve_up_leg", "round_trip_jacobian", "two_way_range_partials", "up_rate_partials",
           "two_way_range_rate_partials"]

#: Measurement kinds the estimator models (in the order its reports list them).
KINDS = ESTIMATE_KIND_ORDER


def _dot(a, b):
    return np.einsum("...i,...i->...", a, b)


# ----------------------------------------------------------------------------- light time

@dataclass(frozen=True)
class EmissionGeometry:
    """Result of :func:`solve_light_time` (arrays along the samples).

    ``t_e_s`` emission times (s, the trajectory's time axis), ``tau_s`` light times,
    ``state`` (N, 6) and ``state_dot`` (N, 6; None when not asked for) of the satellite at ``t_e``, ``rho_m`` ranges,
    ``u`` unit vectors station -> satellite, ``iterations`` Newton iterations taken.
    """

    t_e_s: np.ndarray
    tau_s: np.ndarray
    state: np.ndarray
    state_dot: np.ndarray
    rho_m: np.ndarray
    u: np.ndarray
    iterations: int


def solve_light_time(trajectory, t_r_s, r_st, *, c: float = C_LIGHT, tol_s: float = LIGHT_TIME_TOL_S,
                     max_iter: int = 10, tau0=None, derivative: bool = True) -> EmissionGeometry:
    """Emission times of one-way signals received at ``r_st`` (N, 3) at ``t_r_s`` (N,).

    ``trajectory.state(t, derivative=0|1)`` gives the satellite's GCRF ``(r, v)`` or ``(v, a)``
    at any times (dense output). Newton on ``g(τ) = c τ - ρ(t_r - τ)``, ``g' = c + û·v``,
    from ``τ = |r(t_r) - r_st|/c``, or from ``tau0`` (N,) when given (the light times of an earlier
    evaluation on the same samples: Newton's second step is then below ``tol_s`` as it is from the
    cold start, and one trajectory evaluation is spared); converged when every ``|Δτ| < tol_s``
    (1e-12 s: 0.3 mm). Raises ``ArithmeticError`` if it does not converge in ``max_iter`` iterations.
    ``derivative=False``: ``state_dot`` is None (read only by the partials).
    """
    t_r = np.asarray(t_r_s, float)
    r_st = np.asarray(r_st, float)
    if tau0 is None or np.shape(tau0) != t_r.shape or not np.isfinite(tau0).all():
        tau0 = np.linalg.norm(trajectory.state(t_r)[:, :3] - r_st, axis=-1) / c
    last = []

    def state_at(tau):
        # the leg reads the state again at its converged τ: the last iterate's when the final
        # Newton step is below τ's rounding (quadratic convergence makes it so)
        key = tau.tobytes()
        if not last or last[0] != key:
            last[:] = [key, trajectory.state(t_r - tau)]
        return last[1]

    leg = lt.solve_down_leg(state_at, r_st, tau0, c=c, tol_s=tol_s, max_iter=max_iter)
    t_e = t_r - leg.tau_s
    return EmissionGeometry(t_e_s=t_e, tau_s=leg.tau_s, state=leg.state,
                            state_dot=trajectory.state(t_e, derivative=1) if derivative else None,
                            rho_m=leg.rho_m, u=leg.u, iterations=leg.iterations)


def emission_jacobian(u, v_e, state_dot_e, phi_e, c: float = C_LIGHT):
    """Total derivative of the emission state with respect to the parameters, eq. (6).

    ``u`` (N, 3), ``v_e`` (N, 3), ``state_dot_e`` (N, 6) = (v, a) at ``t_e``, ``phi_e`` (N, 6, P) =
    d state(t_e) / d p at fixed ``t_e``. Returns ``D`` (N, 6, P) and ``dt_e/dp`` (N, P).
    """
    drho = np.einsum("ni,nip->np", u, phi_e[:, :3, :]) / (1.0 + _dot(u, v_e) / c)[:, None]
    dte = -drho / c
    return phi_e + state_dot_e[:, :, None] * dte[:, None, :], dte


# ----------------------------------------------------------------------------- measurements

@dataclass
class MeasurementSet:
    """Samples to model, all arrays along the N samples (SI units, GCRF).

    ``t_s`` reception times (s from the solution epoch); ``kind`` (one of :data:`KINDS`);
    ``station`` names; ``pass_id``; ``observed`` and ``sigma``; ``r_st``/``v_st`` (N, 3) the
    station in GCRF at ``t_r``; ``gcrf_to_enu`` (N, 3, 3) for angles (None if there are none);
    ``carrier_hz`` (N,) nominal carrier (NaN where unknown); ``a_st`` (N, 3) the station's GCRF
    (centripetal) acceleration at ``t_r``, needed by two-way samples only (it moves the station
    back over the round trip); ``mode`` (N,) the link, one of :data:`MODES` (default: all
    one-way; it matters for range, range-rate and Doppler samples).
    """

    t_s: np.ndarray
    kind: np.ndarray
    station: np.ndarray
    pass_id: np.ndarray
    observed: np.ndarray
    sigma: np.ndarray
    r_st: np.ndarray
    v_st: np.ndarray
    gcrf_to_enu: Optional[np.ndarray] = None
    carrier_hz: Optional[np.ndarray] = None
    a_st: np.ndarray | None = None
    mode: np.ndarray | None = None

    def __post_init__(self) -> None:
        self.kind = np.asarray(self.kind, dtype=object)
        self.station = np.asarray(self.station, dtype=object)
        self.pass_id = np.asarray(self.pass_id, dtype=object)
        n = len(self.t_s)
        if self.carrier_hz is None:
            self.carrier_hz = np.full(n, np.nan)
        self.carrier_hz = np.broadcast_to(np.asarray(self.carrier_hz, float), (n,)).copy()
        self.mode = np.broadcast_to(np.asarray("one-way" if self.mode is None else self.mode, dtype=object),
                                    (n,)).copy()
        if self.a_st is not None:
            self.a_st = np.asarray(self.a_st, float)
        bad = sorted(set(self.kind.tolist()) - set(KINDS))
        if bad:
            raise ValueError(f"unknown measurement kind {bad[0]!r}; expected one of {KINDS}")
        bad = sorted(set(self.mode.tolist()) - set(MODES))
        if bad:
            raise ValueError(f"unknown link mode {bad[0]!r}; expected one of {MODES}")

    def __len__(self) -> int:
        return len(self.t_s)

    def is_kind(self, kind: str) -> np.ndarray:
        """``self.kind == kind``, kept with the kind array it was computed from (a model evaluation
        asks the same few kinds of the same samples many times)."""
        kept = self.__dict__.get("_kind_masks")
        if kept is None or kept[0] is not self.kind:
            kept = self.__dict__["_kind_masks"] = (self.kind, {})
        mask = kept[1].get(kind)
        if mask is None:
            mask = kept[1][kind] = self.kind == kind
        return mask.copy()

    @property
    def periodic(self) -> np.ndarray:
        """True for azimuth samples (residuals wrap at 2π)."""
        return self.kind == "azimuth"

    @property
    def two_way(self) -> np.ndarray:
        """True for two-way range, range-rate and Doppler samples (the round-trip model); kept with
        the mode and kind arrays it was computed from (each model evaluation asks)."""
        kept = self.__dict__.get("_two_way")
        if kept is None or kept[0] is not self.mode or kept[1] is not self.kind:
            two = self.mode == "two-way"
            two = two & np.isin(self.kind, LINK_KINDS) if two.any() else two
            kept = self.__dict__["_two_way"] = (self.mode, self.kind, two)
        return kept[2].copy()

    def shifted(self, dt_s) -> "MeasurementSet":
        """The samples as if received ``dt_s`` (s, scalar or per row) later: ``t_s + dt`` and the
        station (position, velocity, acceleration, ENU axes) turned with the Earth by ``|ω| dt``
        about its rotation axis ``ω = (v_st × a_st) / |v_st|²`` (a fixed site: ``v = ω × r``,
        ``a = ω × v``; Rodrigues' rotation formula), the axis along GCRF z at
        :data:`~trackproc.constants.OMEGA_EARTH` without ``a_st``. Precession-nutation over
        seconds is left out (below 1e-10 rad)."""
        dt = np.broadcast_to(np.asarray(dt_s, float), (len(self),))
        if self.a_st is not None:
            w = np.cross(self.v_st, self.a_st) / np.einsum("ij,ij->i", self.v_st, self.v_st)[:, None]
        else:
            w = np.tile([0.0, 0.0, OMEGA_EARTH], (len(self), 1))
        rate = np.linalg.norm(w, axis=1)
        k = w / rate[:, None]
        angle = rate * dt
        cos, sin = np.cos(angle)[:, None], np.sin(angle)[:, None]

        def turn(x):                                 # (n, 3) vectors or (n, m, 3) rows of matrices
            kk = k if x.ndim == 2 else k[:, None, :]
            c, s_ = (cos, sin) if x.ndim == 2 else (cos[:, None], sin[:, None])
            kx = np.cross(kk, x)
            return x * c + kx * s_ + kk * (np.sum(kk * x, axis=-1, keepdims=True)) * (1.0 - c)

        return MeasurementSet(t_s=self.t_s + dt, kind=self.kind, station=self.station, pass_id=self.pass_id,
                              observed=self.observed, sigma=self.sigma, r_st=turn(self.r_st), v_st=turn(self.v_st),
                              gcrf_to_enu=None if self.gcrf_to_enu is None else turn(self.gcrf_to_enu),
                              carrier_hz=self.carrier_hz, a_st=None if self.a_st is None else turn(self.a_st),
                              mode=self.mode)

    def subset(self, rows) -> "MeasurementSet":
        rows = np.asarray(rows)
        pick = (lambda a: None if a is None else a[rows])
        return MeasurementSet(t_s=self.t_s[rows], kind=self.kind[rows], station=self.station[rows],
                              pass_id=self.pass_id[rows], observed=self.observed[rows], sigma=self.sigma[rows],
                              r_st=self.r_st[rows], v_st=self.v_st[rows], gcrf_to_enu=pick(self.gcrf_to_enu),
                              carrier_hz=self.carrier_hz[rows], a_st=pick(self.a_st), mode=self.mode[rows])


#: A modifier bound to a measurement set (the name the estimator used before modifiers owned drivers).
BiasModifier = md.BoundModifier


def bias_modifiers(meas: MeasurementSet, names: Sequence[str], epochs: dict | None = None,
                   c: float = C_LIGHT) -> list[md.BoundModifier]:
    """The bound modifiers owning the bias drivers ``names`` on ``meas`` (state names are skipped),
    for callers that hold names rather than modifiers (:func:`trackproc.models.modifiers.from_name`).

    ``range_bias:S`` -> ranges of station S; ``az_bias:S``/``el_bias:S`` -> its angles;
    ``doppler_offset:K`` and ``doppler_drift:K`` -> Doppler and range-rate samples whose pass id
    or station is K (range-rate through ``-c/f``, ``-c/(2f)`` two-way; NaN carrier there raises
    ValueError).
    ``epochs`` maps a drift name to its reference time (s). A driver touching no sample raises
    ValueError (it would be unobservable).

    Implements seed 002 eq. 10 (the E block of the offsets D0 of the extended state; Doppler offsets alike).
    """
    epochs = epochs or {}
    out = []
    for name in names:
        if name in STATE_NAMES:
            continue
        out.append(md.from_name(name, epochs.get(name)).bind(meas))
    return out


def evaluate(meas: MeasurementSet, trajectory, *, n_state_params: int = 6, modifiers: Sequence[BiasModifier] = (),
             bias_values: dict | None = None, bias_columns: dict | None = None, n_columns: int | None = None,
             range_rate_model: str = "doppler", c: float = C_LIGHT, partials: bool = True, tau0=None):
    """Model values and partials of every sample (eqs. (1)-(13) of the module docstring).

    ``trajectory`` gives GCRF ``state(t, derivative=0|1)`` (N, 6) and ``stm(t)`` (N, 6, P) —
    d state(t) / d (state at the epoch), P = ``n_state_params`` columns placed first (a
    :class:`trackproc.dynamics.propagator.Trajectory` propagated with ``stm=True``).
    ``modifiers`` (:class:`~trackproc.models.modifiers.BoundModifier`, e.g. from
    :func:`trackproc.models.modifiers.bind_all`), with ``bias_values`` driver name -> value and
    ``bias_columns`` name -> column of the Jacobian (omit a name to hold it fixed: value added,
    no column). Two-way samples (``meas.two_way``) take the round trip, eqs. (7)-(13), and need
    ``meas.a_st``. Returns ``(computed (N,), jacobian (N, n_columns), geometry)``, the geometry
    being the down leg's (:class:`EmissionGeometry`; for two-way samples ``t_e`` is the bounce).

    A modifier that shifts time (:class:`~trackproc.models.modifiers.StationTimeBias`, ``τ``)
    moves its rows' reception times to ``t - τ`` before everything else, and its column is
    ``-ḣ(t - τ)``, by a central difference of the model (:func:`_time_partials`).

    ``partials=False``: the values alone (the same numbers), the Jacobian None; ``trajectory.stm``
    is not read (a step rule's trial point needs no Jacobian). ``tau0``: the down leg's light
    times of an earlier evaluation, where :func:`solve_light_time` starts (the same numbers to
    its tolerance).

    Implements seed 002 eq. 17 (with light time, station motion and the offsets) and its Jacobian (eq. 10).

    Over 100 lines with this docstring; its code is under 100.
    """
    _check_model(range_rate_model)
    n = len(meas)
    bias_values = bias_values or {}
    bias_columns = bias_columns or {}
    timed = [m for m in modifiers if m.modifier.shifts_time and m.rows.size]
    if timed:
        dt = np.zeros(n)
        for m in timed:
            dt[m.rows] -= float(bias_values.get(m.name, 0.0))
        if np.any(dt):
            meas = meas.shifted(dt)
    ncol = n_columns if n_columns is not None else n_state_params + len(bias_columns)
    geo = solve_light_time(trajectory, meas.t_s, meas.r_st, c=c, tau0=tau0, derivative=partials)
    r_e, v_e = geo.state[:, :3], geo.state[:, 3:]
    if partials:
        phi = trajectory.stm(geo.t_e_s)
        dstate, _ = emission_jacobian(geo.u, v_e, geo.state_dot, phi, c)
    value = np.empty(n)
    g = np.zeros((n, 6))                            # ∂ value / ∂ s_e

    kind = meas.kind
    two = meas.two_way
    up = None
    if two.any():
        if meas.a_st is None:
            raise ValueError("two-way samples need the station acceleration a_st")
        up = solve_up_leg(r_e[two], meas.r_st[two], meas.v_st[two], meas.a_st[two], geo.tau_s[two], c=c)
        g_t = np.zeros(n)                           # ∂ value / ∂ T at fixed s_b (eq. 12)
        pos = np.cumsum(two) - 1                    # row -> index in the up-leg arrays
    m = meas.is_kind("range")
    value[m] = geo.rho_m[m]
    g[m, :3] = geo.u[m]
    if up is not None and (m & two).any():
        rows = np.flatnonzero(m & two)
        j = pos[rows]
        value[rows], g[rows, :3], g_t[rows] = two_way_range_partials(geo.rho_m[rows], geo.u[rows], up.rho_m[j],
                                                                     up.u[j], up.v_st[j])
    for k in ("range_rate", "doppler"):
        m = meas.is_kind(k)
        if not m.any():
            continue
        sel = m if not m.all() else slice(None)     # every row (one kind): no selection's copies
        rr, d_r, d_v = range_rate_partials(_rows(r_e, sel), _rows(v_e, sel), _rows(meas.r_st, sel),
                                           _rows(meas.v_st, sel), range_rate_model, c, rho=geo.rho_m[sel],
                                           u=geo.u[sel])
        factor = 1.0 if k == "range_rate" else -_rows(meas.carrier_hz, sel) / c
        if k == "doppler" and not np.isfinite(factor).all():
            raise ValueError("Doppler samples need a carrier frequency")
        if np.shape(factor) != rr.shape:
            factor = np.broadcast_to(factor, rr.shape)
        tm = two[m]
        if tm.any():
            rows = np.flatnonzero(m)[tm]
            j = pos[rows]
            rr[tm], d_r[tm], d_v[tm], d_t = two_way_range_rate_partials(
                r_e[rows], v_e[rows], meas.r_st[rows], meas.v_st[rows], up.r_st[j], up.v_st[j], meas.a_st[rows],
                range_rate_model, c)
            if k == "doppler":
                factor = np.where(tm, 2.0 * factor, factor)     # eq. (10): the round trip doubles the shift
            g_t[rows] = factor[tm] * d_t
        value[sel] = factor * rr
        g[sel, :3] = factor[:, None] * d_r
        g[sel, 3:] = factor[:, None] * d_v
    ang = meas.is_kind("azimuth") | meas.is_kind("elevation")
    if ang.any():
        if meas.gcrf_to_enu is None:
            raise ValueError("angle samples need gcrf_to_enu")
        az, el, d_az, d_el = azel_partials(r_e[ang] - meas.r_st[ang], meas.gcrf_to_enu[ang])
        is_az = kind[ang] == "azimuth"
        value[ang] = np.where(is_az, az, el)
        g[ang, :3] = np.where(is_az[:, None], d_az, d_el)

    jac = np.zeros((n, ncol))
    if partials:
        jac[:, :n_state_params] = np.einsum("ni,nip->np", g, dstate)
        if up is not None:
            d_big_t = round_trip_jacobian(geo.u[two], up.u, up.v_st, dstate[two, :3, :n_state_params], c)
            jac[two, :n_state_params] += g_t[two, None] * d_big_t
    for mod in modifiers:
        mod.apply(value, jac, bias_values, bias_columns, geo)
    if not partials:
        return value, None, geo
    for mod in timed:
        col = bias_columns.get(mod.name)
        if col is not None:
            jac[mod.rows, col] += _time_partials(meas, mod.rows, trajectory, n_state_params, range_rate_model, c)
    return value, jac, geo


def _rows(a, sel):
    """``a[sel]``: a copy in C order for a boolean ``sel``, as for ``slice(None)`` (every row) where
    ``a`` is not already C-ordered: the same operands either way, without the selection's copy."""
    return np.ascontiguousarray(a) if isinstance(sel, slice) else a[sel]


def _time_partials(meas: MeasurementSet, rows, trajectory, n_state_params: int, range_rate_model: str,
                   c: float) -> np.ndarray:
    """``∂h/∂τ = -ḣ`` of ``rows`` of ``meas`` (already at their true times ``t - τ``): a central
    difference of the model (without modifiers) in the reception time, half step
    :data:`~trackproc.models.modifiers.TIME_STEP_S` (azimuth differences wrapped)."""
    sub = meas.subset(rows)
    h = md.TIME_STEP_S
    later, earlier = (evaluate(sub.shifted(s), trajectory, n_state_params=n_state_params, n_columns=n_state_params,
                               range_rate_model=range_rate_model, c=c)[0] for s in (h, -h))
    diff = later - earlier
    diff = np.where(sub.periodic, wrap_pi(diff), diff)
    return -diff / (2.0 * h)


# ----------------------------------------------------------------------------- two-way (eqs. 7-13)

def round_trip_jacobian(u_down, u_up, v_st_t, dstate_r, c: float = C_LIGHT):
    """``dT/dp`` (N, P) of the round-trip light time, eq. (11).

    ``u_down``, ``u_up`` (N, 3) the legs' unit vectors, ``v_st_t`` (N, 3) the station's velocity
    ``V`` at ``t_t``, ``dstate_r`` (N, 3, P) the position rows of the bounce state's total
    derivative ``D`` (:func:`emission_jacobian`).
    """
    num = np.einsum("ni,nip->np", np.asarray(u_down) + np.asarray(u_up), dstate_r)
    return num / (c - _dot(u_up, v_st_t))[:, None]

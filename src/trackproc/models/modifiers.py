"""Measurement modifiers: corrections to the modelled observables that own their parameter drivers.

Orekit's estimation design (``EstimationModifier``: ``getParametersDrivers()`` and ``modify()``):
each correction of a measurement model — a station's range bias, a transmitter's frequency
offset and drift, an antenna's azimuth/elevation bias, the wander of an oscillator, a
troposphere delay — is one object that

* owns the :class:`~trackproc.models.parameters.ParameterDriver` objects it depends on
  (:meth:`Modifier.parameter_drivers`; none for a correction that is known, not estimated);
* knows the samples it acts on (:meth:`Modifier.rows`);
* applies itself to the modelled values and adds its partials to the Jacobian
  (:meth:`BoundModifier.apply`, after :meth:`Modifier.bind` to one measurement set).

The estimator collects the drivers from its modifiers (:func:`collect_drivers`); nothing
parses parameter names to find out what a driver does — neither ``estimate`` nor ``refine``,
which builds its problem with estimate's and binds the same modifiers to the quadrature nodes
of its integral cost. Adding a bias kind is one subclass here (and its family name in
:data:`trackproc.vocabulary.BIAS_UNITS`); it is then estimated by both when given in
``EstimateOptions.modifiers`` / ``RefineOptions.modifiers`` (tests/pipeline/test_refine_modifiers.py
does that with a toy kind), and a command-line option that creates it is the one further
edit (``pipeline.od.modifiers.bias_modifiers``, as ``--range-bias`` does).

Linear modifiers add ``Σ_k coefficient_k × value_k`` of their drivers, so their partials are
the coefficients (seed 002 eq. 10: the E block of the extended state's offsets):

    range bias          1 on the station's ranges (a two-way range's half round trip)
    Doppler offset      1 on Doppler (Hz); -c/f on range-rate from one-way Doppler
                        (ρ̇ = -c Δf / f), -c/(2f) from two-way Doppler (ρ̇ = -c Δf / (2f))
    Doppler drift       the offset's coefficient × (t_r - t0)
    Doppler step        the offset's coefficient on the samples from t0 on (an oscillator step)
    azimuth, elevation  1 on the station's azimuths / elevations (rad)

A :class:`StationTimeBias` (``time_bias:STATION``, s) is not additive: the station's time tags
are late by ``τ``, so a sample tagged ``t`` is the measurement of the true reception time
``t - τ``, ``h_obs(t) = h(t - τ)``, and ``∂h/∂τ = -ḣ(t - τ)`` for every kind (range: the
range-rate; range-rate and Doppler: the range acceleration; angles: their rates). The model
(:func:`trackproc.models.observation.evaluate`) moves the samples' reception times by ``-τ``
before the light time (:meth:`~trackproc.models.observation.MeasurementSet.shifted`, the station
turned with the Earth) — exact, not linearised — and takes ``ḣ`` by a central difference of the
model in the reception time (:data:`TIME_STEP_S`). The additive modifiers stay on the tags (a
transmitter drift runs on the satellite's clock, not the station's).

A :class:`RangeCorrection` adds a known delay (m) with no estimated driver (troposphere,
centre-of-mass offset: subclasses give :meth:`RangeCorrection.delay`, evaluated on each model
evaluation's geometry, :func:`elevation`); its dependence on the orbit is left out of the
Jacobian (a troposphere delay changes by millimetres per kilometre of orbit change).

:class:`OscillatorWander` is the stochastic part of a one-way transmitter's frequency: a random
walk of intensity ``q`` (Hz/√s) started at the offset's epoch. It adds nothing to the modelled
value; it is marginalised in the noise covariance (:mod:`trackproc.methods.noise`, the batch
form of frequency nodes with a random-walk prior between them), and this object says which
samples it concerns and whether its intensity is given or to be estimated.

Pure numpy; nothing here reads files or prints.
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import Iterable, Optional, Sequence

import numpy as np

from trackproc.constants import C_LIGHT
from trackproc.dynamics import geodesy
from trackproc.models import parameters as pm
from trackproc.models.observables import range_rate_per_hz

__all__ = ["Modifier", "BoundModifier", "RangeBias", "DopplerOffset", "DopplerDrift", "DopplerStep", "AzimuthBias",
           "ElevationBias", "StationTimeBias", "RangeCorrection", "OscillatorWander", "elevation", "collect_drivers",
           "bind_all",
           "from_name", "FAMILIES"]


@dataclass(frozen=True)
class BoundModifier:
    """A modifier bound to one measurement set ``meas``: the rows it acts on and its coefficients.

    ``coefficient`` (len(rows), n_drivers) holds the partials of the rows' values with respect
    to ``names`` (None: all ones, one driver). A known correction (:meth:`Modifier.correction`)
    is evaluated at each :meth:`apply`, on that evaluation's geometry.
    """

    modifier: "Modifier"
    names: tuple
    rows: np.ndarray
    coefficient: Optional[np.ndarray] = None
    meas: object = None

    @property
    def name(self) -> str:
        """The driver's name (single-driver modifiers; ``""`` for a driver-free correction)."""
        return self.names[0] if self.names else ""

    def coefficients(self, k: int = 0) -> np.ndarray:
        """The partials of the rows with respect to driver ``k``."""
        if self.coefficient is None:
            return np.ones(len(self.rows))
        return np.asarray(self.coefficient, float)[:, k]

    def apply(self, value: np.ndarray, jac: np.ndarray, values: dict, columns: dict, geometry=None) -> None:
        """Add the modifier's effect to ``value`` and its partials to the ``columns`` of ``jac``
        (driver name -> column; a driver not in ``columns`` is held fixed at ``values[name]``).
        ``geometry``: the evaluation's :class:`~trackproc.models.observation.EmissionGeometry`,
        for corrections that depend on where the satellite is (a troposphere delay)."""
        if self.rows.size == 0 or self.modifier.shifts_time:
            return                                  # a time offset acts in the model itself (evaluate)
        corr = self.modifier.correction(self.meas, self.rows, geometry)
        if corr is not None:
            value[self.rows] += corr
        for k, name in enumerate(self.names):
            coef = self.coefficients(k)
            value[self.rows] += coef * values.get(name, 0.0)
            col = columns.get(name)
            if col is not None:
                jac[self.rows, col] += coef


class Modifier:
    """A correction of modelled observables that owns its drivers (Orekit's ``EstimationModifier``).

    Subclasses set :attr:`family` (the driver family, a key of
    :data:`trackproc.vocabulary.BIAS_UNITS`; None for a driver-free correction), :attr:`scale`
    and :attr:`description` of the driver, and implement :meth:`rows`; linear ones
    :meth:`partials`, driver-free ones :meth:`correction`.
    """

    family: Optional[str] = None
    scale: float = 1.0
    description: str = ""
    #: True for a modifier whose driver is an offset (s) of the rows' reception times, applied
    #: by :func:`trackproc.models.observation.evaluate` before the light time (not additive).
    shifts_time: bool = False
    #: the driver's bounds (a time offset must stay inside the propagated span's margin)
    bounds: tuple = (-np.inf, np.inf)

    def __init__(self, key: str, reference: float = 0.0, *, apriori_sigma: Optional[float] = None,
                 selected: bool = True, scale: Optional[float] = None, epoch_s: Optional[float] = None) -> None:
        self.key = key
        self._drivers: list = []
        if self.family is not None:
            d = pm.family_driver(self.family, key, reference, self.scale if scale is None else scale, apriori_sigma,
                                 epoch_s=epoch_s, description=self.description, bounds=self.bounds)
            d.selected = bool(selected)
            self._drivers.append(d)

    def __repr__(self) -> str:
        return f"{type(self).__name__}({self.key!r})"

    def parameter_drivers(self) -> list:
        """The drivers this modifier depends on (Orekit's ``getParametersDrivers()``)."""
        return list(self._drivers)

    @property
    def driver(self):
        """The single driver (None for a driver-free modifier)."""
        return self._drivers[0] if self._drivers else None

    def rows(self, meas) -> np.ndarray:
        """Indices of the samples of ``meas`` this modifier acts on."""
        raise NotImplementedError

    def partials(self, meas, rows) -> Optional[np.ndarray]:
        """(len(rows), n_drivers) partials; None = ones (a plain bias)."""
        return None

    def correction(self, meas, rows, geometry) -> Optional[np.ndarray]:
        """A known value added to the rows at each evaluation (None: none); ``geometry`` the
        evaluation's emission geometry (None when evaluated without one)."""
        return None

    def bind(self, meas) -> BoundModifier:
        """This modifier on ``meas``; ValueError when a modifier with drivers acts on no sample
        (they would be unobservable; a driver-free one simply does nothing)."""
        rows = np.asarray(self.rows(meas), int)
        names = tuple(d.name for d in self._drivers)
        if rows.size == 0 and names:
            raise ValueError(f"parameter {names[0] if names else repr(self)!r} acts on no measurement")
        coef = self.partials(meas, rows)
        if coef is not None:
            coef = np.asarray(coef, float).reshape(rows.size, len(names))
        return BoundModifier(self, names, rows, coef, meas)


# ----------------------------------------------------------------------------- station biases

class _StationBias(Modifier):
    """A bias of one kind of a station's samples (coefficient 1)."""

    kind = ""

    def rows(self, meas) -> np.ndarray:
        return np.flatnonzero((meas.kind == self.kind) & (meas.station == self.key))


class RangeBias(_StationBias):
    """``range_bias:STATION`` (m): ``D_meas = D + D0``. Implements seed 002 eq. 10 (offset D0, E block)."""

    family, kind, scale = "range_bias", "range", 10.0
    description = "range bias added to every range of the station (seed 002 D0)"


class AzimuthBias(_StationBias):
    """``az_bias:STATION`` (rad), added to the modelled azimuth."""

    family, kind, scale, description = "az_bias", "azimuth", 1e-4, "azimuth bias"


class ElevationBias(_StationBias):
    """``el_bias:STATION`` (rad), added to the modelled elevation."""

    family, kind, scale, description = "el_bias", "elevation", 1e-4, "elevation bias"


#: Largest |time_bias| (s): the propagated span reaches this far beyond the samples
#: (``pipeline.od.problem.Problem.trajectory``).
TIME_BIAS_LIMIT_S = 30.0
#: Half step (s) of the central difference giving a sample's time derivative (truncation
#: the third derivative times δ²/6: below 1e-6 of ``ḣ`` on a LEO pass).
TIME_STEP_S = 0.05


class StationTimeBias(Modifier):
    """``time_bias:STATION`` (s): every sample of the station is tagged ``τ`` late (``h_obs(t) =
    h(t - τ)``); applied in the model (:attr:`Modifier.shifts_time`), partial ``-ḣ(t - τ)``."""

    family, scale, shifts_time = "time_bias", 0.01, True
    bounds = (-TIME_BIAS_LIMIT_S, TIME_BIAS_LIMIT_S)
    description = "time-tag offset of the station's samples (tags late by this; h_obs(t) = h(t - tau))"

    def rows(self, meas) -> np.ndarray:
        return np.flatnonzero(meas.station == self.key)


# ----------------------------------------------------------------------------- transmitter frequency

def _frequency_rows(meas, key) -> np.ndarray:
    """Doppler and range-rate samples whose pass id or station is ``key``."""
    owner = (meas.pass_id == key) | (meas.station == key)
    return np.flatnonzero(owner & ((meas.kind == "doppler") | (meas.kind == "range_rate")))


def _hz_to_samples(meas, rows, coef, name, c=C_LIGHT) -> np.ndarray:
    """``coef`` (Hz per unit of the driver) on Doppler rows; ``-c/f`` (one-way) or ``-c/(2f)``
    (two-way) times it on range-rate rows (ρ̇ = -c Δf / f, resp. / (2f): :func:`range_rate_per_hz`)."""
    rr = meas.kind[rows] == "range_rate"
    if rr.any():
        f = meas.carrier_hz[rows][rr]
        if not np.all(np.isfinite(f) & (f > 0)):
            raise ValueError(f"{name}: range-rate samples without a carrier frequency cannot take a "
                             "Doppler offset/drift")
        coef = coef.copy()
        coef[rr] *= range_rate_per_hz(f, meas.two_way[rows][rr], c)
    return coef


class DopplerOffset(Modifier):
    """``doppler_offset:KEY`` (Hz): the transmitter's frequency offset, on the Doppler and
    range-rate samples of a pass or station ``KEY``."""

    family, scale = "doppler_offset", 1.0
    description = "one-way Doppler frequency offset (received - nominal)"

    def rows(self, meas) -> np.ndarray:
        return _frequency_rows(meas, self.key)

    def partials(self, meas, rows) -> np.ndarray:
        return _hz_to_samples(meas, rows, np.ones(rows.size), self.driver.name)


class DopplerDrift(Modifier):
    """``doppler_drift:KEY`` (Hz/s): the offset grows as ``drift × (t_r - t0)``, ``t0`` the
    driver's epoch (s from the solution epoch; the pass's first sample)."""

    family, scale = "doppler_drift", 1e-3
    description = "one-way Doppler frequency drift"

    def __init__(self, key: str, epoch_s: float, reference: float = 0.0, **kw) -> None:
        super().__init__(key, reference, epoch_s=float(epoch_s), **kw)

    def rows(self, meas) -> np.ndarray:
        return _frequency_rows(meas, self.key)

    def partials(self, meas, rows) -> np.ndarray:
        return _hz_to_samples(meas, rows, meas.t_s[rows] - self.driver.epoch_s, self.driver.name)


class DopplerStep(Modifier):
    """``doppler_step:KEY`` (Hz): a change of the transmitter's frequency offset from ``t0`` on
    (an oscillator's level shift inside a pass), ``t0`` the driver's epoch (s from the solution
    epoch): the offset's coefficient on the samples received at or after ``t0``, 0 before."""

    family, scale = "doppler_step", 1.0
    description = "one-way Doppler frequency step (offset change from the driver's epoch on)"

    def __init__(self, key: str, epoch_s: float, reference: float = 0.0, **kw) -> None:
        super().__init__(key, reference, epoch_s=float(epoch_s), **kw)

    def rows(self, meas) -> np.ndarray:
        rows = _frequency_rows(meas, self.key)
        return rows[meas.t_s[rows] >= self.driver.epoch_s]

    def partials(self, meas, rows) -> np.ndarray:
        return _hz_to_samples(meas, rows, np.ones(rows.size), self.driver.name)


class OscillatorWander(Modifier):
    """The random walk of a one-way transmitter's frequency (pass or station ``KEY``), of
    intensity ``walk`` (Hz/√s; None = estimated from the data by REML). No driver and no
    deterministic effect: it is marginalised in the pass's noise covariance
    (:mod:`trackproc.methods.noise`), the batch form of frequency nodes with a random-walk prior."""

    def __init__(self, key: str, walk: Optional[float] = None) -> None:
        super().__init__(key)
        self.walk = walk

    def rows(self, meas) -> np.ndarray:
        rows = _frequency_rows(meas, self.key)
        return rows[~meas.two_way[rows]]           # a coherent two-way link has no free oscillator


# ----------------------------------------------------------------------------- known corrections

class RangeCorrection(Modifier):
    """A known correction (m) of ranges, no estimated driver: subclasses give :meth:`delay`
    (troposphere, centre-of-mass offset, a calibrated station delay). ``station`` None = every
    station."""

    def __init__(self, station: Optional[str] = None) -> None:
        super().__init__(station or "*")
        self.station = station

    def rows(self, meas) -> np.ndarray:
        m = meas.kind == "range"
        if self.station is not None:
            m &= meas.station == self.station
        return np.flatnonzero(m)

    def delay(self, meas, rows, geometry) -> np.ndarray:
        """Metres added to the modelled range of ``rows`` (``geometry``: see :meth:`Modifier.correction`;
        :func:`elevation` gives the satellite's elevation from it)."""
        raise NotImplementedError

    def correction(self, meas, rows, geometry) -> np.ndarray:
        return np.broadcast_to(np.asarray(self.delay(meas, rows, geometry), float), rows.shape)


def elevation(meas, rows, geometry) -> np.ndarray:
    """The satellite's elevation (rad) seen from the station at the samples ``rows``: the
    geometry's station -> satellite direction in the station's east-north-up frame."""
    enu = np.einsum("nij,nj->ni", meas.gcrf_to_enu[rows], geometry.u[rows])
    return geodesy.enu_to_azel(enu)[1]


# ----------------------------------------------------------------------------- registry

#: Modifier class of each driver family (for names given as text: files, tests, ``--apriori-sigma``).
FAMILIES = {cls.family: cls for cls in (RangeBias, DopplerOffset, DopplerDrift, DopplerStep, AzimuthBias,
                                        ElevationBias, StationTimeBias)}


def from_name(name: str, epoch_s: Optional[float] = None, **kw) -> Modifier:
    """The modifier owning the driver ``name`` (``FAMILY:KEY``); ``epoch_s`` for a drift."""
    family, key = pm.split_name(name)
    cls = FAMILIES.get(family)
    if cls is None:
        raise ValueError(f"{name!r} is not a measurement modifier's parameter")
    if cls in (DopplerDrift, DopplerStep):
        if epoch_s is None:
            raise ValueError(f"{name}: no reference epoch for the {'drift' if cls is DopplerDrift else 'step'}")
        return cls(key, epoch_s, **kw)
    return cls(key, **kw)


def collect_drivers(modifiers: Iterable[Modifier]) -> list:
    """Every driver of ``modifiers`` in order (the estimator's extended state after x..vz)."""
    return [d for m in modifiers for d in m.parameter_drivers()]


def bind_all(modifiers: Sequence[Modifier], meas) -> list:
    """:meth:`Modifier.bind` of each modifier on ``meas``."""
    return [m.bind(meas) for m in modifiers]

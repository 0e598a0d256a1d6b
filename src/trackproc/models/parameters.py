"""Estimated-parameter registry: the extended state vector as a list of named drivers.

Every estimable quantity is a :class:`ParameterDriver` (after Orekit's ``ParameterDriver``):
a name, a unit, a reference value (the starting point), a scale (about the expected
uncertainty, so that the normal equations are well scaled), optional bounds, an optional
a-priori sigma (and a-priori value, the reference by default) and a ``selected`` flag. A
:class:`ParameterSet` holds them in order, refuses duplicate names, and gives the estimator
the selected ones as plain arrays.

Names (the part after ``:`` is a station or pass id)::

    x y z vx vy vz                 state at the solution epoch, GCRF (m, m/s)
    range_bias:STATION             added to every range of the station (m)
    doppler_offset:KEY             added to one-way Doppler (Hz) of a pass or station
    doppler_drift:KEY              Hz/s, times (t - epoch of the driver)
    az_bias:STATION  el_bias:STATION   added to azimuth / elevation (rad)
    r_ka                           radius of refine's circular-orbit constraints (m, seed 004 eq. 5)
    cr  cd                         radiation-pressure and drag coefficients (force model)
    empirical_r empirical_t empirical_n   constant empirical acceleration, R/T/N (m/s^2)
    empirical_x empirical_y empirical_z   the same along the GCRF axes (m/s^2)
    empirical_x_rate ...           its growth along X, Y, Z per second from the epoch (m/s^3)

This is seed 002's extended state vector (m motion parameters + N offsets, eq. 10) done
generally: the measurement modifiers (:mod:`trackproc.models.modifiers`) own the bias drivers
and the estimator collects them from the modifiers (the factory functions below remain for
callers that only need a driver).

Pure Python and numpy; nothing here reads files or prints.
"""

from __future__ import annotations

import math
from dataclasses import dataclass, field
from typing import Iterable, Iterator, Optional

import numpy as np

from trackproc import vocabulary

__all__ = ["ParameterDriver", "ParameterSet", "DuplicateParameterError", "STATE_NAMES", "KINDS",
           "state_drivers", "range_bias", "doppler_offset", "doppler_drift", "az_bias", "el_bias",
           "split_name", "family_driver", "orbit_radius", "CONSTRAINT_NAMES", "FORCE_NAMES",
           "force_parameter"]

#: Names of the six state components, in order.
STATE_NAMES = vocabulary.STATE_NAMES
#: Parameter families with a key after ``:``, and their units.
KINDS = vocabulary.BIAS_UNITS
#: Parameters of constraints (not of a measurement): refine's circular-orbit radius, and units.
CONSTRAINT_NAMES = vocabulary.CONSTRAINT_PARAMETERS
#: Force-model parameters (``estimate --estimate-force``) and units; their partials come from
#: the propagator's variational equations, not from a measurement modifier.
FORCE_NAMES = vocabulary.FORCE_PARAMETERS
#: Default scales (about one expected sigma): state m and m/s, then by family.
DEFAULT_SCALES = {"position": 100.0, "velocity": 0.1, "range_bias": 10.0, "doppler_offset": 1.0,
                  "doppler_drift": 1e-3, "doppler_step": 1.0, "az_bias": 1e-4, "el_bias": 1e-4, "time_bias": 0.01,
                  "cr": 0.1, "cd": 0.1,
                  "empirical_r": 1e-9, "empirical_t": 1e-9, "empirical_n": 1e-9, "empirical_x": 1e-9,
                  "empirical_y": 1e-9, "empirical_z": 1e-9, "empirical_x_rate": 1e-13, "empirical_y_rate": 1e-13,
                  "empirical_z_rate": 1e-13}


class DuplicateParameterError(ValueError):
    """A parameter name was registered twice."""


@dataclass
class ParameterDriver:
    """One estimable quantity.

    Attributes
    ----------
    name : str
        Unique name, e.g. ``"vx"`` or ``"range_bias:KIR"`` (no whitespace).
    unit : str
        SI unit of the value (``"m"``, ``"m/s"``, ``"Hz"``, ``"Hz/s"``, ``"rad"``).
    reference : float
        Reference (initial) value; the current ``value`` starts here.
    scale : float
        Positive scale: the estimator solves for ``(value - reference) / scale``.
    apriori_sigma : float or None
        1-sigma of an a-priori constraint ``value ~ apriori_value``; None = no constraint.
    apriori_value : float or None
        Centre of the a-priori constraint (default: ``reference``).
    selected : bool
        Estimated when True; held at ``value`` when False.
    bounds : (float, float)
        Allowed interval of the value (the estimator clips steps into it).
    epoch_s : float or None
        A reference time (s from the solution epoch) for drift-like parameters.
    description : str
        Free text for reports.
    """

    name: str
    unit: str
    reference: float = 0.0
    scale: float = 1.0
    apriori_sigma: Optional[float] = None
    apriori_value: Optional[float] = None
    selected: bool = True
    bounds: tuple = (-math.inf, math.inf)
    epoch_s: Optional[float] = None
    description: str = ""
    value: float = field(default=math.nan)

    def __post_init__(self) -> None:
        if not isinstance(self.name, str) or not self.name or any(c.isspace() for c in self.name):
            raise ValueError(f"parameter name must be a non-empty string without spaces; found {self.name!r}")
        self.reference = float(self.reference)
        self.scale = float(self.scale)
        if not math.isfinite(self.reference):
            raise ValueError(f"{self.name}: reference value must be finite; found {self.reference}")
        if not (math.isfinite(self.scale) and self.scale > 0):
            raise ValueError(f"{self.name}: scale must be a positive number; found {self.scale}")
        if self.apriori_sigma is not None:
            self.apriori_sigma = float(self.apriori_sigma)
            if not (math.isfinite(self.apriori_sigma) and self.apriori_sigma > 0):
                raise ValueError(f"{self.name}: a-priori sigma must be positive; found {self.apriori_sigma}")
        if self.apriori_value is not None:
            self.apriori_value = float(self.apriori_value)
        lo, hi = (float(b) for b in self.bounds)
        if not lo < hi:
            raise ValueError(f"{self.name}: bounds must satisfy min < max; found {self.bounds}")
        self.bounds = (lo, hi)
        if math.isnan(self.value):
            self.value = self.reference
        if not lo <= self.reference <= hi:
            raise ValueError(f"{self.name}: reference {self.reference} outside bounds {self.bounds}")

    @property
    def family(self) -> str:
        """``"state"`` for x..vz, the name for a constraint or force parameter (``r_ka``, ``cr``), else
        the part before ``:``."""
        return "state" if self.name in STATE_NAMES else split_name(self.name)[0]

    @property
    def key(self) -> Optional[str]:
        """The station or pass id after ``:`` (None for state components)."""
        return None if self.name in STATE_NAMES else split_name(self.name)[1]

    @property
    def prior_centre(self) -> float:
        return self.reference if self.apriori_value is None else self.apriori_value

    def normalized(self, value: float | None = None) -> float:
        """``(value - reference) / scale``."""
        return ((self.value if value is None else value) - self.reference) / self.scale


def split_name(name: str) -> tuple[str, Optional[str]]:
    """``"range_bias:KIR"`` -> ``("range_bias", "KIR")``; ``"vx"`` -> ``("state", None)``;
    ``"r_ka"`` -> ``("r_ka", None)``.

    Raises ValueError for an unknown family or an empty key.
    """
    if name in STATE_NAMES:
        return "state", None
    if name in CONSTRAINT_NAMES or name in FORCE_NAMES:
        return name, None
    family, sep, key = name.partition(":")
    if not sep or not key or family not in KINDS:
        raise ValueError(f"unknown parameter name {name!r}; expected one of {', '.join(STATE_NAMES)} or "
                         f"FAMILY:KEY with FAMILY in {', '.join(KINDS)}")
    return family, key


class ParameterSet:
    """Drivers in registration order; names unique; the selected ones form the estimated vector.

    >>> ps = ParameterSet(state_drivers([7e6, 0, 0, 0, 7.5e3, 0]))
    >>> _ = ps.add(range_bias("KIR"))
    >>> ps.selected_names
    ['x', 'y', 'z', 'vx', 'vy', 'vz', 'range_bias:KIR']
    >>> ps.add(range_bias("KIR"))
    Traceback (most recent call last):
    ...
    trackproc.models.parameters.DuplicateParameterError: duplicate parameter 'range_bias:KIR'
    """

    def __init__(self, drivers: Iterable[ParameterDriver] = ()) -> None:
        self._drivers: list[ParameterDriver] = []
        self._index: dict[str, int] = {}
        for d in drivers:
            self.add(d)

    # -- registration -------------------------------------------------------------------------
    def add(self, driver: ParameterDriver) -> ParameterDriver:
        """Register ``driver``; :class:`DuplicateParameterError` if its name is taken."""
        if driver.name in self._index:
            raise DuplicateParameterError(f"duplicate parameter {driver.name!r}")
        self._index[driver.name] = len(self._drivers)
        self._drivers.append(driver)
        return driver

    def __iter__(self) -> Iterator[ParameterDriver]:
        return iter(self._drivers)

    def __len__(self) -> int:
        return len(self._drivers)

    def __contains__(self, name: str) -> bool:
        return name in self._index

    def __getitem__(self, name: str) -> ParameterDriver:
        try:
            return self._drivers[self._index[name]]
        except KeyError:
            raise KeyError(f"no parameter {name!r}") from None

    def get(self, name: str) -> Optional[ParameterDriver]:
        return self._drivers[self._index[name]] if name in self._index else None

    @property
    def names(self) -> list[str]:
        return [d.name for d in self._drivers]

    # -- the estimated vector -----------------------------------------------------------------
    @property
    def selected(self) -> list[ParameterDriver]:
        return [d for d in self._drivers if d.selected]

    @property
    def selected_names(self) -> list[str]:
        return [d.name for d in self._drivers if d.selected]

    def index(self, name: str) -> int:
        """Column of ``name`` in the selected vector (ValueError when not selected)."""
        names = self.selected_names
        if name not in names:
            raise ValueError(f"parameter {name!r} is not selected")
        return names.index(name)

    def values(self) -> np.ndarray:
        """Current values of the selected drivers."""
        return np.array([d.value for d in self.selected], float)

    def set_values(self, values) -> None:
        """Set the selected drivers' values (in order)."""
        values = np.asarray(values, float)
        sel = self.selected
        if values.shape != (len(sel),):
            raise ValueError(f"expected {len(sel)} values; found shape {values.shape}")
        for d, v in zip(sel, values):
            d.value = float(v)

    def references(self) -> np.ndarray:
        return np.array([d.reference for d in self.selected], float)

    def scales(self) -> np.ndarray:
        return np.array([d.scale for d in self.selected], float)

    def units(self) -> list[str]:
        return [d.unit for d in self.selected]

    def bounds(self) -> tuple[np.ndarray, np.ndarray]:
        sel = self.selected
        return (np.array([d.bounds[0] for d in sel], float), np.array([d.bounds[1] for d in sel], float))

    def apriori(self) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        """``(mask, centre, sigma)`` over the selected drivers (sigma NaN where none)."""
        sel = self.selected
        mask = np.array([d.apriori_sigma is not None for d in sel], bool)
        centre = np.array([d.prior_centre for d in sel], float)
        sigma = np.array([d.apriori_sigma if d.apriori_sigma is not None else np.nan for d in sel], float)
        return mask, centre, sigma

    def family_of(self) -> list[str]:
        return [d.family for d in self.selected]


# ------------------------------------------------------------------------------ constructors

def state_drivers(rv, *, scale_m: float = DEFAULT_SCALES["position"],
                  scale_m_s: float = DEFAULT_SCALES["velocity"], sigma=None) -> list[ParameterDriver]:
    """The six state drivers ``x..vz`` (m, m/s) with reference ``rv`` (6,).

    ``sigma`` (6,) optional a-priori sigmas (None entries or NaN = none).
    """
    rv = np.asarray(rv, float).reshape(6)
    out = []
    for i, name in enumerate(STATE_NAMES):
        s = None
        if sigma is not None and sigma[i] is not None and np.isfinite(sigma[i]):
            s = float(sigma[i])
        out.append(ParameterDriver(name, "m" if i < 3 else "m/s", float(rv[i]), scale_m if i < 3 else scale_m_s,
                                   apriori_sigma=s, description="GCRF state at the solution epoch"))
    return out


def family_driver(family: str, key: str, reference: float, scale: float | None, apriori_sigma, **kw):
    """The driver ``FAMILY:KEY`` (unit from the vocabulary, default scale by family)."""
    if not isinstance(key, str) or not key or any(c.isspace() for c in key):
        raise ValueError(f"{family} key must be a non-empty string without spaces; found {key!r}")
    return ParameterDriver(f"{family}:{key}", KINDS[family], reference,
                           DEFAULT_SCALES[family] if scale is None else scale, apriori_sigma=apriori_sigma, **kw)


def range_bias(station: str, reference: float = 0.0, *, scale: float | None = None,
               apriori_sigma: float | None = None) -> ParameterDriver:
    """``range_bias:STATION`` (m): ``D_meas = D + D0`` (seed 002, one-way phase ranging)."""
    return family_driver("range_bias", station, reference, scale, apriori_sigma,
                          description="range bias added to every range of the station (seed 002 D0)")


def doppler_offset(key: str, reference: float = 0.0, *, scale: float | None = None,
                   apriori_sigma: float | None = None) -> ParameterDriver:
    """``doppler_offset:KEY`` (Hz): frequency offset of one-way Doppler (pass or station)."""
    return family_driver("doppler_offset", key, reference, scale, apriori_sigma,
                          description="one-way Doppler frequency offset (received - nominal)")


def doppler_drift(key: str, epoch_s: float, reference: float = 0.0, *, scale: float | None = None,
                  apriori_sigma: float | None = None) -> ParameterDriver:
    """``doppler_drift:KEY`` (Hz/s): Doppler offset grows as ``drift * (t - epoch_s)``."""
    return family_driver("doppler_drift", key, reference, scale, apriori_sigma, epoch_s=float(epoch_s),
                          description="one-way Doppler frequency drift")


def az_bias(station: str, reference: float = 0.0, *, scale: float | None = None,
            apriori_sigma: float | None = None) -> ParameterDriver:
    """``az_bias:STATION`` (rad), added to the modelled azimuth."""
    return family_driver("az_bias", station, reference, scale, apriori_sigma, description="azimuth bias")


def el_bias(station: str, reference: float = 0.0, *, scale: float | None = None,
            apriori_sigma: float | None = None) -> ParameterDriver:
    """``el_bias:STATION`` (rad), added to the modelled elevation."""
    return family_driver("el_bias", station, reference, scale, apriori_sigma, description="elevation bias")


def orbit_radius(reference: float, *, scale: float = DEFAULT_SCALES["position"],
                 apriori_sigma: float | None = None) -> ParameterDriver:
    """``r_ka`` (m): the radius of the circular-orbit constraints ``|r|² = r_ka²``,
    ``|v|² = μ/r_ka`` of refine (seed 004 eq. 5), a parameter of the constraints, not of a measurement."""
    return ParameterDriver("r_ka", CONSTRAINT_NAMES["r_ka"], reference, scale, apriori_sigma=apriori_sigma,
                           bounds=(0.0, math.inf), description="circular-orbit radius (seed 004 eq. 5)")


def force_parameter(name: str, reference: float, *, scale: float | None = None,
                    apriori_sigma: float | None = None) -> ParameterDriver:
    """A force-model parameter (``cr``, ``cd``, ``empirical_r/t/n``) at its model value ``reference``.

    The coefficients are bounded below by 0 (a negative Cr or Cd is not physical); the empirical
    accelerations are free. Their partials are the propagator's parameter sensitivities
    (Montenbruck & Gill 2000 eq. 7.44, :mod:`trackproc.dynamics.forces.integrator`)."""
    if name not in FORCE_NAMES:
        raise ValueError(f"unknown force parameter {name!r}; expected one of {', '.join(FORCE_NAMES)}")
    bounds = (0.0, math.inf) if name in ("cr", "cd") else (-math.inf, math.inf)
    what = {"cr": "radiation-pressure coefficient", "cd": "drag coefficient", "empirical_r": "radial",
            "empirical_t": "along-track", "empirical_n": "cross-track", "empirical_x": "GCRF X",
            "empirical_y": "GCRF Y", "empirical_z": "GCRF Z"}[name.removesuffix("_rate")]
    if name.endswith("_rate"):
        what = "rate of the empirical acceleration (times t from the epoch), " + what
    elif name.startswith("empirical"):
        what = "constant empirical acceleration, " + what
    return ParameterDriver(name, FORCE_NAMES[name], reference, DEFAULT_SCALES[name] if scale is None else scale,
                           apriori_sigma=apriori_sigma, bounds=bounds, description=what)

"""An orbit state (:class:`State`): epoch, GCRF position and velocity, parameters, covariance and
what produced them. Read and written by :mod:`trackproc.io.statefile`."""

from __future__ import annotations

from dataclasses import dataclass, field
from typing import Optional

import numpy as np

from trackproc.dynamics.timescales import datetime64_to_jd_utc
from trackproc.types.epoch import parse_epoch

STATE_PARAMETERS = ("x", "y", "z", "vx", "vy", "vz")


@dataclass
class State:
    """An orbit state at an epoch, in GCRF, with optional extended parameters and covariance.

    ``epoch`` is UTC ``datetime64[ns]``; ``jd_utc`` the same instant as a two-part UTC Julian
    date (ERFA convention). ``r_m`` (3,) and ``v_m_s`` (3,) are GCRF. ``parameters`` names
    the estimated parameters in order (the six state components first, as
    :data:`STATE_PARAMETERS`, when present); ``values``, ``sigma`` and ``covariance``
    (n × n, rows/columns following ``parameters``) may be None. ``force_model`` is a
    ``--force`` key (``"two-body"``, ``"j2"``) or, for a file from elsewhere, its own label;
    ``constants`` the constants it used; ``eop_source`` the Earth-orientation input;
    ``diagnostics`` the solution's diagnostics; ``extra`` any other top-level keys.
    """

    epoch: np.datetime64
    jd_utc: tuple
    r_m: np.ndarray
    v_m_s: np.ndarray
    parameters: list = field(default_factory=lambda: list(STATE_PARAMETERS))
    values: Optional[np.ndarray] = None
    sigma: Optional[np.ndarray] = None
    covariance: Optional[np.ndarray] = None
    force_model: Optional[str] = None
    constants: dict = field(default_factory=dict)
    eop_source: Optional[str] = None
    diagnostics: dict = field(default_factory=dict)
    extra: dict = field(default_factory=dict)
    source: Optional[str] = None

    @classmethod
    def from_vectors(cls, epoch, r_m, v_m_s, **kwargs) -> "State":
        """A GCRF state at a UTC epoch (``datetime64``, or ISO 8601 text)."""
        t = parse_epoch(epoch) if isinstance(epoch, str) else np.datetime64(epoch, "ns")
        jd1, jd2 = datetime64_to_jd_utc(t)
        return cls(epoch=t, jd_utc=(float(jd1), float(jd2)), r_m=np.asarray(r_m, float).reshape(3).copy(),
                   v_m_s=np.asarray(v_m_s, float).reshape(3).copy(), **kwargs)

    @property
    def rv(self) -> np.ndarray:
        """Position and velocity as one (6,) vector (m, m/s)."""
        return np.concatenate([self.r_m, self.v_m_s])

    @property
    def state_covariance(self) -> Optional[np.ndarray]:
        """The 6 × 6 covariance of position and velocity, when the parameters include them."""
        if self.covariance is None:
            return None
        index = [self.parameters.index(p) for p in STATE_PARAMETERS if p in self.parameters]
        if len(index) != 6:
            return None
        return self.covariance[np.ix_(index, index)]

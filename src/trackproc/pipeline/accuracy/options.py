"""The options, the limits and the result of ``trackproc accuracy``; the initial covariance (step 1).
"""

from __future__ import annotations

import math
from dataclasses import dataclass, field
from typing import Optional, Sequence

import numpy as np
import pandas as pd

from trackproc.errors import InputError
from trackproc.methods import accuracy as ac
from trackproc.types import STATE_PARAMETERS
from trackproc.vocabulary import FORCES


METHODS = ("spectral", "stm", "monte-carlo", "all")


#: Monte Carlo sample count when the method asks for it and --monte-carlo does not say.
DEFAULT_MONTE_CARLO = 1000
#: Draws propagated together in one batch (memory: chunk x times x 6 floats).
MC_CHUNK = 1000
MAX_TIMES = 1_000_000
MAX_MONTE_CARLO = 1_000_000
#: Largest grid for the correlation matrix R(t_i, t_j) (pairs grow as the square).
MAX_CORRELATION_TIMES = 500
#: Column prefix of each method when it is not the first (unprefixed) one.
PREFIX = {"spectral": "spectral_", "stm": "stm_", "monte-carlo": "mc_"}
#: (name, unit suffix, unit) of the six inertial and six RTN components.
COMPONENTS = (("x", "m", "m"), ("y", "m", "m"), ("z", "m", "m"),
              ("vx", "m_s", "m/s"), ("vy", "m_s", "m/s"), ("vz", "m_s", "m/s"))
RTN_COMPONENTS = (("radial", "m", "m"), ("along", "m", "m"), ("cross", "m", "m"),
                  ("v_radial", "m_s", "m/s"), ("v_along", "m_s", "m/s"), ("v_cross", "m_s", "m/s"))
RTN_CONVENTION = ("radial = r/|r|, cross = r x v/|r x v|, along = cross x radial, at the nominal state; "
                  "v_radial, v_along, v_cross = rates of change of the radial/along/cross position errors "
                  "(M dv - w x M dr, w = |r x v|/r^2 about cross: the Clohessy-Wiltshire convention)")


@dataclass
class AccuracyOptions:
    """Options of :func:`accuracy` (units in the names). ``monte_carlo`` = N draws (None: the
    default N when the method needs them, else no Monte Carlo); sigmas are 1 or 3 values, on
    ``sigma_frame`` axes (``gcrf`` or ``rtn``)."""

    span_s: float
    step_s: float
    force: str = "j2"
    method: str = "spectral"
    #: The ForceModel of ``force="full"`` (trackproc.dynamics.forces; cli.force_options builds it).
    force_model: Optional[object] = None
    monte_carlo: Optional[int] = None
    seed: Optional[int] = None
    sigma_position_m: Optional[Sequence[float]] = None
    sigma_velocity_m_s: Optional[Sequence[float]] = None
    sigma_frame: str = "gcrf"
    at_station: Optional[str] = None
    earth: str = "wgs84"
    correlation: bool = False

    @property
    def methods(self) -> tuple:
        """Methods to run, the first one giving the unprefixed columns."""
        if self.method == "all":
            return ("spectral", "stm", "monte-carlo")
        if self.method == "monte-carlo":
            return ("monte-carlo",)
        return (self.method,) + (("monte-carlo",) if self.monte_carlo is not None else ())

    @property
    def n_samples(self) -> Optional[int]:
        if "monte-carlo" not in self.methods:
            return None
        return DEFAULT_MONTE_CARLO if self.monte_carlo is None else int(self.monte_carlo)


@dataclass
class AccuracyResult:
    """Result of :func:`accuracy`.

    ``frame``: one row per time (see the module docstring); ``meta``: provenance and checks;
    ``times`` (M,) UTC ``datetime64[ns]``; ``elapsed_s`` (M,); ``nominal`` (M, 6) GCRF;
    ``covariance`` and ``covariance_rtn``: method -> (M, 6, 6); ``observables``: method ->
    (M, 2, 2) covariance of range and range-rate (with a station); ``initial_covariance``
    (6, 6) GCRF; ``correlation``: None or {"method", "cov": component -> (M, M)}.
    """

    frame: pd.DataFrame
    meta: dict
    times: np.ndarray
    elapsed_s: np.ndarray
    nominal: np.ndarray
    covariance: dict
    covariance_rtn: dict
    observables: dict
    initial_covariance: np.ndarray
    correlation: Optional[dict] = None
    station_track: Optional[dict] = field(default=None, repr=False)


def check_options(options: AccuracyOptions) -> None:
    def positive(flag, value):
        if not (isinstance(value, (int, float)) and math.isfinite(value) and value > 0):
            raise InputError("must be positive", column=flag, found=value, expected="a number > 0")

    positive("--span", options.span_s)
    positive("--step", options.step_s)
    if options.span_s / options.step_s > MAX_TIMES:
        raise InputError("too many times", column="--step", found=options.step_s,
                         expected=f"at most {MAX_TIMES} steps over --span")
    if options.method not in METHODS:
        raise InputError("unknown method", column="--method", found=options.method, expected=" | ".join(METHODS))
    if options.force not in FORCES:
        raise InputError("unknown force model", column="--force", found=options.force, expected=" or ".join(FORCES))
    if options.force == "full" and options.n_samples:
        # each draw would be a full DOP853 integration (about a second per day of LEO): not offered
        raise InputError("Monte Carlo draws use the Taylor engine's batch mode (two-body, j2)", column="--method",
                         found=f"{options.method} with --force full",
                         expected="--method spectral or stm (no --monte-carlo) with --force full")
    if options.monte_carlo is not None and not (2 <= int(options.monte_carlo) <= MAX_MONTE_CARLO):
        raise InputError("invalid sample count", column="--monte-carlo", found=options.monte_carlo,
                         expected=f"an integer in [2, {MAX_MONTE_CARLO}]")
    if options.sigma_frame not in ("gcrf", "rtn"):
        raise InputError("unknown frame", column="--sigma-frame", found=options.sigma_frame, expected="gcrf or rtn")
    if options.correlation and options.span_s / options.step_s + 1 > MAX_CORRELATION_TIMES + 1e-9:
        raise InputError("too many times for the correlation matrix", column="--correlation",
                         found=f"{int(options.span_s / options.step_s) + 1} times",
                         expected=f"at most {MAX_CORRELATION_TIMES} (a larger --step or a shorter --span)")


def _sigma_triplet(values, flag) -> np.ndarray:
    v = np.atleast_1d(np.asarray(values, dtype=float))
    if v.size == 1:
        v = np.repeat(v, 3)
    if v.size != 3 or not np.all(np.isfinite(v)) or np.any(v < 0):
        raise InputError("invalid sigma", column=flag, found=",".join(repr(float(x)) for x in v),
                         expected="one value or three comma-separated values, each >= 0")
    return v


def initial_covariance(state, options: AccuracyOptions) -> tuple[np.ndarray, str]:
    """The 6 x 6 GCRF covariance of the initial state and a description of where it came from.

    Raises :class:`InputError` naming the state file and the field when there is none.
    """
    pos, vel = options.sigma_position_m, options.sigma_velocity_m_s
    if (pos is None) != (vel is None):
        missing = "--sigma-velocity-m-s" if vel is None else "--sigma-position-m"
        raise InputError("give both sigma options", column=missing,
                         expected="--sigma-position-m and --sigma-velocity-m-s together")
    if pos is not None:
        sig = np.concatenate([_sigma_triplet(pos, "--sigma-position-m"),
                              _sigma_triplet(vel, "--sigma-velocity-m-s")])
        cov = np.diag(sig ** 2)
        label = "--sigma-position-m / --sigma-velocity-m-s"
        if options.sigma_frame == "rtn":
            m = ac.rtn_rotation(state.r_m, state.v_m_s)
            big = np.zeros((6, 6))
            big[:3, :3] = big[3:, 3:] = m
            cov = big.T @ cov @ big
            label += " on radial/along/cross axes"
        else:
            label += " on GCRF axes"
        if getattr(state, "state_covariance", None) is not None:
            label += " (the state file's covariance is not used)"
    elif state.state_covariance is not None:
        cov = np.asarray(state.state_covariance, float)
        label = "state file covariance (x .. vz block, GCRF)"
    elif state.sigma is not None and all(p in state.parameters for p in STATE_PARAMETERS):
        idx = [state.parameters.index(p) for p in STATE_PARAMETERS]
        cov = np.diag(np.asarray(state.sigma, float)[idx] ** 2)
        label = "state file sigma (uncorrelated, GCRF)"
    else:
        raise InputError("no initial covariance", file=state.source, column="covariance",
                         expected="a covariance (or sigma) over x, y, z, vx, vy, vz in the state file, "
                                  "or --sigma-position-m and --sigma-velocity-m-s")
    if not np.any(np.diag(cov) > 0):
        raise InputError("the initial covariance is zero", file=state.source if pos is None else None,
                         column="covariance" if pos is None else "--sigma-position-m",
                         expected="at least one positive variance")
    return 0.5 * (cov + cov.T), label

"""Options of ``trackproc filter`` (:class:`FilterOptions`) and their checks."""

from __future__ import annotations

import math
from dataclasses import dataclass, field
from typing import Mapping, Optional

from trackproc.errors import InputError
from trackproc.pipeline.od import EstimateOptions

#: A-priori sigma of a parameter without one, in units of its driver's scale (a diffuse start:
#: range bias 100 km, Doppler offset 10 kHz, drift 10 Hz/s, angle bias 1 rad, Cr/Cd 1000).
DIFFUSE_SCALES = 1e4
#: Bias families whose random walk ``--bias-walk`` may set (unit of the driver per sqrt(s)).
WALK_FAMILIES = ("range_bias", "doppler_offset", "doppler_drift", "az_bias", "el_bias")


@dataclass
class FilterOptions:
    """``problem``: the :class:`EstimateOptions` that build the shared problem (measurement
    models, modifiers, force model, a-priori); ``snc_accel``: state noise compensation, the
    1-sigma density of a white acceleration along radial, along-track, cross-track in
    m/s²/√Hz (its power spectral density is the square, m²/s³); ``bias_walk``: bias family or
    parameter name -> random-walk density (driver unit per √s: m/√s, Hz/√s, ...);
    ``edit_sigma``: a sample whose innovation is beyond this many sigmas of its own innovation
    variance (χ²(1)) is edited (0/None: off); ``smooth``: run the RTS smoother; ``iterations``:
    sweeps of filter and smoother, each linearised about the previous sweep's smoothed states
    (the prior kept); ``segment_gap_s``: a gap between measurement times longer than this ends a
    tracking segment, where the reference trajectory is restarted from the filter's state;
    ``relinearise_m``: the reference is also restarted after a step that leaves the filter's
    position further than this from it (a range's second-order term is δ²/2ρ: 100 m at 500 km
    is 1 cm); ``ekf_sigma_m``: the reference restarts through the filter's state (at a segment
    or after such a step) only once the filter's position sigma (root of the trace) plus its velocity
    sigma times 1000 s is below this, metres; before, the filter is linearised about the current reference (None: always);
    ``dmc``: dynamic model compensation, ``(sigma_r, sigma_t, sigma_n, tau)``: the estimated
    empirical RTN accelerations (``--estimate-force empirical-rtn``) as first-order Gauss–Markov
    processes of steady-state sigma m/s² and time constant tau s (None: constants);
    ``bias_gm``: bias family or parameter name -> ``(sigma, tau)``, a first-order Gauss–Markov
    bias (driver unit, s) instead of a constant or random walk; ``bias_reset``: per-station bias
    families or parameters (``range_bias``, ``range_bias:KIR``, ``az_bias``, ``el_bias``) that
    restart from their a-priori at each new pass of their station;
    ``output_epoch``: UTC datetime64 of the written state (None: the last measurement, with
    ``smooth`` the first filter time)."""

    problem: EstimateOptions = field(default_factory=EstimateOptions)
    snc_accel: tuple = (0.0, 0.0, 0.0)
    bias_walk: Mapping[str, float] = field(default_factory=dict)
    edit_sigma: Optional[float] = 5.0
    smooth: bool = False
    iterations: int = 1
    segment_gap_s: float = 300.0
    relinearise_m: float = 100.0
    ekf_sigma_m: Optional[float] = 1000.0
    dmc: Optional[tuple] = None
    bias_gm: Mapping[str, tuple] = field(default_factory=dict)
    bias_reset: tuple = ()
    output_epoch: object = None
    tolerance_sigma: float = 1e-4


def check_filter_options(opt: FilterOptions) -> None:
    """:class:`InputError` naming the option for a value out of range."""
    if len(opt.snc_accel) != 3 or not all(math.isfinite(a) and a >= 0 for a in opt.snc_accel):
        raise InputError("state noise compensation must be three densities >= 0", column="--snc-accel",
                         found=",".join(str(a) for a in opt.snc_accel), expected="R,T,N in m/s^2/sqrt(Hz), or one value")
    for key, v in opt.bias_walk.items():
        if not (isinstance(v, (int, float)) and math.isfinite(v) and v >= 0):
            raise InputError("a random-walk density must be >= 0", column="--bias-walk", found=f"{key}={v}",
                             expected="NAME=DENSITY in the parameter's unit per sqrt(s)")
    if opt.dmc is not None:
        vals = tuple(opt.dmc)
        if len(vals) != 4 or not all(math.isfinite(v) and v > 0 for v in vals):
            raise InputError("dynamic model compensation needs sigmas > 0 and a time constant > 0", column="--dmc",
                             found=",".join(str(v) for v in vals), expected="SIGMA[,TAU] or R,T,N,TAU in m/s^2 and s")
    for key, v in opt.bias_gm.items():
        ok = len(tuple(v)) == 2 and all(isinstance(a, (int, float)) and math.isfinite(a) for a in v)
        if not ok or v[0] <= 0 or v[1] <= 0:
            raise InputError("a Gauss-Markov bias needs a sigma > 0 and a time constant > 0", column="--bias-gm",
                             found=f"{key}={v}", expected="NAME=SIGMA,TAU (the parameter's unit, s)")
        if key in opt.bias_walk:
            raise InputError("a bias is a random walk or a Gauss-Markov process, not both", column="--bias-gm",
                             found=key, expected="NAME in --bias-walk or --bias-gm")
    if opt.iterations < 1:
        raise InputError("at least one sweep", column="--iterations", found=opt.iterations, expected=">= 1")
    if opt.iterations > 1 and not opt.smooth:
        raise InputError("iterating the filter needs the smoother", column="--iterations", found=opt.iterations,
                         expected="--smooth with --iterations > 1")

"""Options of ``trackproc estimate`` and their checks (:class:`EstimateOptions`, :func:`check_options`)."""

from __future__ import annotations

import math
from dataclasses import dataclass, field
from typing import Mapping, Optional, Sequence

from trackproc.dynamics import propagator
from trackproc.errors import InputError
from trackproc.models import observation as ob
from trackproc.models import parameters as pm
from trackproc import vocabulary
from trackproc.vocabulary import DOPPLER_BIASES, ESTIMATE_DOPPLER_BIASES, KIND_UNITS, NOISE_MODELS


#: Unit of each kind's values (SI).
UNITS = KIND_UNITS
DOPPLER_BIAS = DOPPLER_BIASES
DOPPLER_BIAS_PER = ("pass", "station")
#: Margin (s) added before the first sample so that emission times are covered.
LIGHT_TIME_MARGIN_S = 1.0
#: Names that stand for several parameters in ``apriori_sigma``.
GROUPS = {"position": ("x", "y", "z"), "velocity": ("vx", "vy", "vz"), "state": pm.STATE_NAMES,
          "empirical": ("empirical_r", "empirical_t", "empirical_n", "empirical_x", "empirical_y", "empirical_z"),
          "empirical_rate": ("empirical_x_rate", "empirical_y_rate", "empirical_z_rate")}
RESIDUAL_COLUMNS = ("time", "station", "pass_id", "kind", "unit", "observed", "computed", "residual",
                    "normalized_residual", "sigma", "edited")


@dataclass
class EstimateOptions:
    """Options of :func:`estimate` (defaults = the CLI's).

    ``range_bias``: estimate a range bias for every station with ranges (True), for the listed
    stations, or none (False); ``doppler_bias``: ``"auto"`` (an offset and a drift for each pass of
    one-way Doppler, whose transmitter is the satellite's own oscillator; nothing for two-way
    links and range-rate), ``"none"`` (or None), ``"offset"`` or ``"offset+drift"`` (on every pass
    with Doppler or range-rate samples),
    ``doppler_bias_per``: ``"pass"`` or ``"station"``; ``angle_bias``: azimuth and elevation
    biases per station with angles; ``apriori_sigma``: name -> 1-sigma (a parameter name, a
    family such as ``range_bias``, or ``position``/``velocity``/``state``); ``apriori_initial``:
    use the initial state's 6 × 6 covariance as an a-priori constraint (refine's default element
    a-priori for a state without one, e.g. a TLE); None: on for a TLE (a guess whose accuracy is
    known, which one station's passes cannot replace), off otherwise; ``epoch``: the solution
    epoch (None = the initial state's; ``"first"`` = the first sample; or a UTC datetime64);
    ``kinds``: kinds to use (None = all); ``range_rate_model``: None = from the pass files
    (default doppler); ``compare_doppler_only``, ``two_stage``: the seed 002 reports.
    ``noise``: the noise model of each pass's Doppler/range-rate samples (:func:`pass_noise`):
    ``"auto"`` (chosen per pass by REML among white, AR(1), and for one-way passes with a
    frequency offset a random walk of the transmitter frequency and both; then GLS), ``"white"``
    (independent samples), or one of ``"ar1"``, ``"walk"``, ``"ar1+walk"``;
    ``oscillator_noise``: the random-walk intensity (Hz/√s) instead of estimating it.
    ``troposphere`` (auto | mendes-pavlis | none), ``com_offset_m``, ``wavelength_nm``,
    ``solid_tides``: the known corrections of range samples (:mod:`trackproc.pipeline.range_corrections`).
    ``estimate_force``: force-model parameters to estimate with ``force="full"`` (``cr``, ``cd``,
    ``empirical_r``/``_t``/``_n`` or ``empirical-rtn`` for the three, ``empirical_x``/``_y``/``_z``
    or ``empirical-xyz`` along the GCRF axes), started from the force
    model's values (:func:`force_parameter_names`).
    ``station_time_bias``: estimate a time-tag offset (:class:`~trackproc.models.modifiers.StationTimeBias`)
    for every station (True), for the listed stations, or none (False); its a-priori sigma is
    ``--apriori-sigma time_bias[:STATION]``, else the station's ``time_sigma_s`` (a station whose
    ``time_sigma_s`` is 0 has exact tags: no offset is estimated for it).
    ``modifiers``: further :class:`~trackproc.models.modifiers.Modifier` instances (a bias kind
    without an option of its own), applied and their drivers estimated like the ones above
    (copied per problem: their drivers' values do not leak between problems).
    """

    range_bias: bool | Sequence[str] = False
    doppler_bias: Optional[str] = "auto"
    doppler_bias_per: str = "pass"
    angle_bias: bool = False
    station_time_bias: bool | Sequence[str] = False
    apriori_sigma: Mapping[str, float] = field(default_factory=dict)
    apriori_initial: Optional[bool] = None
    #: Days over which the solution must be expected to predict the position better than the initial
    #: state to replace it (``--horizon``; methods/estimation/decision.py); ``allow_keep`` False: always
    #: replace (the rule off, as for a problem without a state a-priori).
    horizon_days: float = 1.0
    allow_keep: bool = True
    force: str = "j2"
    earth: str = "wgs84"
    range_rate_model: Optional[str] = None
    max_iterations: int = 20
    clip: Optional[float] = 4.0
    epoch: object = None
    kinds: Optional[Sequence[str]] = None
    compare_doppler_only: bool = False
    two_stage: bool = False
    rank_rtol: float = 1e-9
    noise: str = "auto"
    oscillator_noise: Optional[float] = None
    force_model: object = None            # force "full": a dynamics.forces.ForceModel (None: default_force_model)
    troposphere: str = "auto"             # range corrections (pipeline.range_corrections)
    com_offset_m: float = 0.0
    wavelength_nm: Optional[float] = None
    solid_tides: Optional[bool] = None    # station solid-Earth tides on ranges (None: on for CRD data)
    estimate_force: Sequence[str] = ()    # force-model drivers (force "full"): cr, cd, empirical-rtn
    modifiers: Sequence = ()              # further measurement modifiers (models.modifiers.Modifier)


def check_options(opt: EstimateOptions) -> None:
    """:class:`InputError` naming the option for any choice outside the vocabulary."""
    if opt.noise not in NOISE_MODELS:
        raise InputError("unknown noise model", column="--noise", found=opt.noise,
                         expected="auto, white, ar1, walk or ar1+walk")
    if opt.oscillator_noise is not None and not (math.isfinite(opt.oscillator_noise) and opt.oscillator_noise > 0):
        raise InputError("the oscillator noise must be positive", column="--oscillator-noise",
                         found=opt.oscillator_noise, expected="a random-walk intensity > 0 in Hz per sqrt(s)")
    if opt.doppler_bias not in (None,) + ESTIMATE_DOPPLER_BIASES:
        raise InputError("unknown Doppler bias model", column="--doppler-bias", found=opt.doppler_bias,
                         expected=" or ".join(ESTIMATE_DOPPLER_BIASES))
    if opt.doppler_bias_per not in DOPPLER_BIAS_PER:
        raise InputError("unknown Doppler bias grouping", column="--doppler-bias-per", found=opt.doppler_bias_per,
                         expected=" or ".join(DOPPLER_BIAS_PER))
    if opt.kinds is not None:
        bad = [k for k in opt.kinds if k not in ob.KINDS]
        if bad or not opt.kinds:
            raise InputError("unknown measurement kind", column="--kinds", found=",".join(bad) or "(none)",
                             expected="a comma list of " + ",".join(ob.KINDS))
    if opt.force not in propagator.FORCES:
        raise InputError("unknown force model", column="--force", found=opt.force, expected=" or ".join(propagator.FORCES))
    names = force_parameter_names(opt.estimate_force)
    if names and opt.force != "full":
        raise InputError("force parameters are estimated with the full force model only", column="--estimate-force",
                         found=",".join(names), expected="--force full")


def force_parameter_names(items: Sequence[str]) -> tuple:
    """``--estimate-force`` items -> force-parameter names in the model's order
    (:data:`trackproc.vocabulary.FORCE_PARAMETERS`); groups expanded; an unknown or repeated
    name is an :class:`InputError`."""
    out = []
    for item in items:
        for part in str(item).split(","):
            part = part.strip().lower()
            if not part:
                continue
            members = vocabulary.FORCE_PARAMETER_GROUPS.get(part, (part.replace("-", "_"),))
            for name in members:
                if name not in vocabulary.FORCE_PARAMETERS:
                    raise InputError("unknown force parameter", column="--estimate-force", found=part,
                                     expected="a comma list of cr, cd, empirical-rtn, empirical-xyz, "
                                              "empirical-xyz-rate or empirical_r/_t/_n/_x/_y/_z/_x_rate/..")
                if name in out:
                    raise InputError("duplicate parameter", column="--estimate-force", found=name,
                                     expected="each parameter once")
                out.append(name)
    return tuple(n for n in vocabulary.FORCE_PARAMETERS if n in out)


def check_apriori(apriori: Mapping[str, float]) -> None:
    """:class:`InputError` for an a-priori sigma that is not a positive number."""
    for key, sigma in apriori.items():
        if not (isinstance(sigma, (int, float)) and math.isfinite(sigma) and sigma > 0):
            raise InputError("a-priori sigma must be positive", column="--apriori-sigma", found=f"{key}={sigma}",
                             expected="NAME=SIGMA with SIGMA > 0")


def apriori_for(name, family, apriori):
    """The a-priori sigma of a parameter from the option's keys (exact name wins)."""
    if name in apriori:
        return apriori[name]
    for group, members in GROUPS.items():
        if name in members and group in apriori:
            return apriori[group]
    if family in apriori:
        return apriori[family]
    return None

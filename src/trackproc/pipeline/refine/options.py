"""The options, the constants and the result types of :mod:`trackproc.pipeline.refine`.
"""

from __future__ import annotations

from dataclasses import dataclass, field
from typing import Mapping, Optional

import numpy as np

from trackproc import vocabulary
from trackproc.vocabulary import REFINE_DOPPLER_BIASES
from trackproc.pipeline.od.residuals import DeferredField


COSTS = ("pointwise", "integral")
DOPPLER_BIAS = REFINE_DOPPLER_BIASES
#: Range-rate-like kinds a Doppler station gives, in order of preference.
RANGE_RATE_KINDS = ("doppler", "range_rate")
#: ``--circular`` is reported as contradicted by the pass below this p-value (:func:`circular_consistency`).
CIRCULAR_TEST_P = 1e-3
#: Links (the pass metadata's ``doppler_mode``): both costs take either.
LINK_MODES = vocabulary.LINK_MODES
#: The a-priori of a stale state that carries no covariance, as independent 1-sigma errors of
#: its non-singular orbital elements (:func:`trackproc.methods.refinement.element_covariance`):
#: a state a day or so old (a TLE, an old solution) is off by kilometres along-track (the
#: phase ``u``: 4e-4 rad = 2.9 km at 7200 km) but knows its period well (``a``: 50 m) and its
#: plane and shape to hundreds of metres (``e`` 5e-5, ``i`` and ``raan`` 1e-4 rad). In RTN at
#: 7200 km: about 360 m radial, 2.9 km along-track, 720 m cross-track, 3 / 0.4 / 0.7 m/s.
#: Pointwise: when the a-posteriori variance factor exceeds this, the sample sigmas are scaled by
#: its square root and the fit repeated (at most :data:`MAX_REWEIGHT` times), so that the stale
#: state and the pass are weighed by the pass's actual scatter, not by nominal sigmas.
REWEIGHT_THRESHOLD = 1.5
MAX_REWEIGHT = 6
#: At most this many re-solves with the a-priori scaled by its variance component (:func:`solve_adapted`).
MAX_APRIORI_ADAPT = 8
MAX_ADAPT_ITERATIONS = 12
#: :func:`refine` re-solves at the refined orbit's own zero range-rate until it is within this of
#: the solution epoch (at most :data:`MAX_TRAVERSE_ITERATIONS` times; else ``traverse_mismatch``).
TRAVERSE_TOLERANCE_S = 0.5
MAX_TRAVERSE_ITERATIONS = 3
#: A pass whose highest elevation is below this gives a weak refinement (see docs/refine.md).
LOW_PASS_DEG = 25.0

NOISE_MODELS = vocabulary.NOISE_MODELS


@dataclass
class RefineOptions:
    """Options of :func:`refine` (defaults = the CLI's).

    ``cost``: ``"pointwise"`` or ``"integral"``; ``circular``: the constraints of seed 004
    eq. 5; ``doppler_bias``: ``"none"``, ``"offset"``, ``"offset+drift"`` or None (= ``offset``
    for one-way Doppler, ``none`` for range-rate); ``apriori``: use the stale state as an
    a-priori (None = yes for ``pointwise``, no for ``integral``); ``apriori_sigma``: name ->
    1-sigma (as ``estimate --apriori-sigma``), overriding the stale covariance and the default;
    ``pass_id``/``kind``: which pass and kind when the file holds several; quadrature:
    ``quadrature_order`` nodes per panel of at most ``quadrature_panel_s`` seconds, over the
    parts of the pass without gaps longer than ``max_gap_s``; ``circular_tolerance``: the
    eccentricity to which the orbit is taken to be circular under ``circular``: the constraints
    are then soft, estimated with the state from their covariance for such an orbit
    (:func:`~trackproc.methods.refinement.solve_soft_kkt`); 0 (the default, the seed's assumption)
    imposes them exactly and makes the covariance conditional on an exactly circular orbit. With
    J2 the osculating eccentricity of a mean-circular LEO orbit swings by ``1.5 J2 (Re/r)^2``
    (about 1e-3): see docs/refine.md before trusting a conditional covariance.
    ``reweight``: weigh the data by their actual scatter (:data:`REWEIGHT_THRESHOLD`).
    ``covariance``: ``"profile"`` (pointwise without ``circular``: the linear covariance plus the
    curvature along the directions the pass cannot see, :meth:`Refinement.profile_covariance`)
    or ``"linear"``.
    ``noise`` (pointwise): the samples' noise model (:mod:`trackproc.methods.noise`): ``"auto"``
    (chosen per pass by REML among white, AR(1), oscillator random walk and both, and, for
    one-way Doppler without ``doppler_bias``, offset or offset+drift), ``"white"`` (independent
    samples: the weighted least squares of before), or one of ``"ar1"``, ``"walk"``,
    ``"ar1+walk"`` (that model, its parameters by REML); ``oscillator_noise``: the random-walk
    intensity of the transmitter frequency (Hz/√s) instead of estimating it.
    ``modifiers``: further measurement modifiers (:class:`~trackproc.models.modifiers.Modifier`),
    passed to the estimator's problem (``EstimateOptions.modifiers``): refine, like estimate,
    collects the drivers from the modifiers and never from parameter names.
    """

    cost: str = "pointwise"
    circular: bool = False
    doppler_bias: Optional[str] = None
    apriori: Optional[bool] = None
    apriori_sigma: Mapping[str, float] = field(default_factory=dict)
    force: str = "j2"
    earth: str = "wgs84"
    range_rate_model: Optional[str] = None
    max_iterations: int = 30
    clip: Optional[float] = 4.0
    pass_id: Optional[str] = None
    kind: Optional[str] = None
    quadrature_order: int = 16
    quadrature_panel_s: float = 30.0
    max_gap_s: float = 30.0
    circular_tolerance: Optional[float] = None
    reweight: bool = True
    rank_rtol: float = 1e-12
    covariance: str = "profile"
    noise: str = "auto"
    oscillator_noise: Optional[float] = None
    #: The solution epoch instead of the smoothed curve's traverse point (UTC datetime64; set by
    #: :func:`refine` when it moves the epoch to the refined orbit's own zero range-rate).
    traverse_epoch: Optional[np.datetime64] = None
    #: Refuse (keep the stale state) when the pass cannot improve it (:func:`refusal_test`).
    allow_refusal: bool = True
    #: 1-sigma uncertainty (s) of the station's time tags, a consider parameter: one pass cannot
    #: see a time-tag offset (docs/refine.md, "Mis-modelled passes"), so its effect is added to the
    #: covariance (:func:`~trackproc.pipeline.refine.traverse.time_tag_covariance`); 0 = exact tags;
    #: None = the station's ``time_sigma_s`` from the stations table or the pass metadata (exact tags without).
    time_tag_sigma_s: Optional[float] = None
    modifiers: tuple = ()
    #: Days after the solution epoch at which the refined state must be expected to predict the
    #: position better than the stale one to replace it (``--horizon``; methods/estimation/decision.py).
    horizon_days: float = 1.0


@dataclass
class SmoothedCurve:
    """The smoothed pass: ``fit`` (a :class:`~trackproc.methods.smoothing.PolynomialFit` in seconds
    from ``epoch``, UTC), its ``tca`` (or None, with ``tca_note``), where it came from
    (``source``: ``"metadata"`` or ``"fitted here"``) and the times ``used_t_s`` of the samples it
    was fitted to (s from ``epoch``)."""

    fit: object
    epoch: np.datetime64
    kind: str
    tca: object
    tca_note: str
    source: str
    used_t_s: np.ndarray


@dataclass
class RefineResult:
    """Everything :func:`refine` produces (the CLI writes it).

    ``state`` (GCRF :class:`~trackproc.io.statefile.State` at the traverse epoch, with every
    parameter, the covariance and the diagnostics), ``stale_epoch_state`` (the same orbit at the
    stale state's epoch), ``solution`` (the solver's), ``problem`` (the estimator's), ``curve``,
    ``residuals`` (one row per sample, as ``estimate --residuals``), ``observability``
    (:class:`~trackproc.methods.refinement.Observability`), ``constraints`` (dict), ``warnings``.
    """

    state: object
    stale_epoch_state: object
    solution: object
    problem: object
    curve: SmoothedCurve
    residuals: pd.DataFrame = DeferredField()        # built when first read (pandas then)
    observability: object
    constraints: dict
    covariance: np.ndarray
    names: list
    warnings: list = field(default_factory=list)
    quality: object = None

"""``trackproc refine``: refine a stale orbit from one Doppler pass of one station (seed 004).

Input: one pass of one station (one- or two-way Doppler or range-rate; raw from ``ingest``/``simulate``
or smoothed by ``smooth``), a stale state (state file, or a TLE evaluated by SGP4 at the traverse
epoch) with an optional covariance, and the station (from ``--stations`` or the pass metadata).

1. **The smoothed curve** (seed 004 eq. 1): the polynomial ``smooth`` stored in the file's
   metadata for this station, pass and kind, or, for a raw pass, the same fit made here
   (:func:`trackproc.pipeline.smooth.smooth`).
2. **The traverse point**: the time of closest approach of that curve (the zero of the
   range-rate; for one-way Doppler, whose transmitter offset is unknown, the inflection point of
   the S-curve, which an offset or a linear drift does not move). The refined state is the GCRF
   state at that epoch; ``r_ka`` is its radius (seed 004 eq. 5).
3. **The problem**: :func:`trackproc.pipeline.estimate.build_problem` with the solution epoch at
   the traverse point: the parameter registry (state, ``doppler_offset:PASS`` and
   ``doppler_drift:PASS`` for one-way Doppler), the measurement model (one-way light time, or
   the round trip of a two-way pass, partials through the light times) and the a-priori
   constraints (the stale covariance moved to the traverse epoch by the state transition
   matrix, or ``--apriori-sigma``, or the documented default :data:`DEFAULT_APRIORI_ELEMENTS`).
4. **The cost**:

   * ``pointwise`` (default, the practical method): weighted least squares on the samples
     themselves with the stale state as an a-priori, solved by
     :func:`trackproc.methods.least_squares.solve` on the estimator's model. A single pass
     cannot determine all six elements; the a-priori keeps the unseen directions where the
     stale state put them, with their stale uncertainty, instead of letting them diverge. Its
     covariance adds to the linear one the curvature along those unseen directions
     (:meth:`Refinement.profile_covariance`; ``covariance="linear"`` leaves it out).
   * ``integral`` (the seed's method): seed 004 eq. 14 by Gauss-Legendre quadrature on the
     smoothed polynomial, the orbit's range-rate and its gradient from the DT spectra
     (:class:`trackproc.methods.refinement.IntegralModel`; for a two-way pass, the seed's own
     ``Vr = c/(2 f0) f_D``, the round-trip model and the Taylor STM), no a-priori unless asked.
     Its covariance propagates the polynomial's coefficient covariance through the estimator
     (:func:`~trackproc.methods.refinement.sandwich_covariance`).

   ``circular=True`` adds the circular-orbit constraints of eq. 5 with ``r_ka`` as a seventh
   parameter, solved by Lagrange multipliers (:func:`~trackproc.methods.refinement.solve_kkt`).
5. **Outputs**: the refined state at the traverse point and at the stale epoch (both with the
   covariance), constraint residuals (and multipliers), an observability report, residuals at
   the samples and the iterations.

:func:`traverse_station` places a station so that a given state is the traverse point of a
visible pass: the seed 004 Table 1 scenario.

The package, by responsibility: :mod:`.options` (options, constants, result types),
:mod:`.selection` (the pass, its smoothed curve, the traverse epoch), :mod:`.problem` (the
assembled :class:`Refinement` and its solves), :mod:`.assemble` (:func:`prepare`),
:mod:`.traverse` (the refined orbit at the pass; :func:`traverse_station`), :mod:`.gates`
(reweighting, a-priori adaptation, improvement test, refusal), :mod:`.noise` (the pass's noise
model), :mod:`.quality` (the verdict), :mod:`.result` (:func:`finish`), :mod:`.run`
(:func:`refine`). The text summary is :func:`trackproc.report.refine_text.summary_text`.
"""

from trackproc.pipeline.refine.options import (  # noqa: F401
    CIRCULAR_TEST_P, COSTS, DOPPLER_BIAS, LINK_MODES, LOW_PASS_DEG, MAX_ADAPT_ITERATIONS,
    MAX_APRIORI_ADAPT, MAX_REWEIGHT, MAX_TRAVERSE_ITERATIONS, NOISE_MODELS, RANGE_RATE_KINDS, REWEIGHT_THRESHOLD,
    TRAVERSE_TOLERANCE_S, RefineOptions, RefineResult, SmoothedCurve)
from trackproc.pipeline.refine.selection import curve_traverse_epoch, select_pass, smoothed_curve  # noqa: F401
from trackproc.pipeline.refine.problem import (  # noqa: F401
    Refinement, default_apriori_covariance, link_mode, state_prior_covariance)
from trackproc.io.tle import is_tle_state  # noqa: F401
from trackproc.pipeline.refine.assemble import apriori_choice, check_options, integral_setup, prepare  # noqa: F401
from trackproc.pipeline.refine.traverse import (  # noqa: F401
    eccentricity, link_range_rate, max_elevation_deg, model_traverse, traverse_station)
from trackproc.pipeline.refine.gates import (  # noqa: F401
    Adapted, Gated, circular_consistency, correlated_conflict_reason, may_refuse, solve_adapted, solve_gated,
    solve_weighted, stale_improvement, with_noise_of)
from trackproc.methods.estimation.prior import DEFAULT_APRIORI_ELEMENTS  # noqa: F401
from trackproc.pipeline.refine.noise import DRIFT_T, noise_model, oscillator_link, solve_noise  # noqa: F401
from trackproc.pipeline.refine.quality import refine_quality  # noqa: F401
from trackproc.pipeline.refine.result import (  # noqa: F401
    at_stale_epoch, constraint_report, finish, integral_method, refine_warnings, without_nuisance)
from trackproc.pipeline.refine.run import refine  # noqa: F401

"""``trackproc fit-tle``: SGP4 mean elements fitted to passes and/or an ephemeris (issue 18 item 3).

Reference behaviour: STRF's ``rffit`` (Doppler curves -> TLE), with this project's honesty rules.

1. **Epoch.** The new TLE's epoch (default: the middle of the last pass) is rounded to what the
   epoch field holds (1e-8 day), so the elements fitted are those written.
2. **Initial elements at that epoch.** The initial orbit (a TLE by SGP4, a state by the J2
   integrator) is sampled every minute over one revolution either side of the epoch and a TLE at
   the epoch is fitted to those GCRF positions (:func:`trackproc.methods.tle_fit.solve`, B* kept):
   it reproduces the initial TLE's own prediction there (metres: same theory).
3. **A-priori.** For a TLE its measured accuracy (:data:`trackproc.methods.tle_fit.TLE_APRIORI`,
   TLE differencing: along-track 200 m at its epoch + 550 m/day, radial 100 m, cross-track 50 m;
   :func:`~trackproc.methods.tle_fit.tle_element_sigmas`); for a state (or ``apriori_model
   "refine"``) refine's default element sigmas (:data:`trackproc.pipeline.refine.DEFAULT_APRIORI_ELEMENTS`:
   a 50 m, e 5e-5, i and Ω 1e-4 rad, argument of latitude 4e-4 rad); B* ``max(|B*|, 1e-4)``;
   carried to the new epoch by the along-track drift a mean-motion error causes
   (:func:`trackproc.methods.tle_fit.age_covariance`).
4. **Model.** Each sample predicted by SGP4 -> GCRF and the foundation measurement model
   (:func:`trackproc.pipeline.orbit_source.station_observables`: light time, one- or two-way,
   the model ``compare`` and ``simulate`` use); an ephemeris row gives three position samples.
   Per pass and kind of one-way Doppler or range-rate, the transmitter's offset and drift
   (``--doppler-bias``, default ``offset+drift``: DopTrack's oscillator drifts 0.3-0.7 Hz/s)
   are nuisance parameters, as ``compare`` fits them.
5. **Fit, editing, noise.** Levenberg-Marquardt on the elements and nuisance terms with the
   a-priori; samples beyond ``clip`` times their group's RMS are edited (three rounds). The
   file's sigmas are then scaled per pass and kind by the RMS of the normalised residuals (when
   above 1) and by the square root of their integrated autocorrelation time ``τ`` (a TLE's
   misfit is smooth in time: ``n`` samples hold ``n/τ`` independent ones;
   :func:`trackproc.pipeline.identify.integrated_autocorrelation_time`) and the fit is repeated
   (its covariance, ``covariance_without_model_error``, is the estimation error alone: see 7).
6. **Verdict** (as refine/estimate, :mod:`trackproc.methods.quality`): ``rejected`` when the
   solver does not converge, the data contradict the a-priori under the fit's own error model
   (:func:`trackproc.methods.tle_theory_error.apriori_conflict_chi2`, SGP4's theory error at each pass
   included, computed after step 7; beyond the 99.9 % point of χ²(free elements)) or, without the a-priori, leave an element over 10x less determined than the default
   a-priori (``undetermined``; ``suspect`` beyond 1x),
   ``suspect`` when more than 10 % of the samples are edited or the written TLE (rounded to its
   fields) lies outside the fitted elements' 99.9 % confidence region (χ² up by more than
   the 99.9 % point of χ²(free elements)); ``ok``
   reasons say how the sigmas were scaled and whether the data improve significantly on the
   initial orbit (the likelihood-ratio test :func:`trackproc.methods.quality.improvement_test`).
7. **SGP4's theory error** (:func:`_model_error`): an analytical theory (and a station's own
   per-pass errors) misses a LEO orbit by far more than the data's noise, differently at each
   pass; it is modelled as an independent per-pass displacement (``--model-error`` times the
   default a-priori's sigmas of e, i, Ω and λ; no mean-motion part), a random effect, the
   elements re-estimated by generalised least squares with it, and the written covariance is
   that of a prediction at a pass (estimation + the pass's own theory error). Its default scale
   is the maximum-likelihood one on the DopTrack development days.
8. **Refusal** (``refused``, suspect): one pass (its along-track drift cannot be told from its own
   theory error), or a fit that predicts the position ``prediction_span_days`` (``--horizon``)
   after the epoch better than the initial orbit with probability below
   :data:`~trackproc.pipeline.fit_tle.options.REFUSAL_PROBABILITY`
   (:func:`trackproc.methods.tle_fit.probability_better`): the initial TLE is written unchanged
   (a state's orbit as a TLE at the epoch), with its covariance; ``refused.fitted_tle`` holds
   the fit.
"""

from trackproc.pipeline.fit_tle.options import (DOPPLER_BIAS, KINDS, FitTleOptions, FitTleResult)  # noqa: F401
from trackproc.pipeline.fit_tle.observations import default_epoch  # noqa: F401
from trackproc.pipeline.fit_tle.checks import cross_validation  # noqa: F401
from trackproc.pipeline.fit_tle.run import fit_tle  # noqa: F401

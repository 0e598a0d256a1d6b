"""``trackproc estimate``: batch weighted least squares of an orbit and its biases (seed 002).

The extended state vector (:mod:`trackproc.models.parameters`): the GCRF state at the solution
epoch, plus the drivers of the measurement modifiers the options ask for
(:mod:`trackproc.models.modifiers`): per-station range biases, per-pass (or per-station)
one-way Doppler frequency offsets and drifts (with the oscillator's wander in the noise model),
and per-station azimuth/elevation biases.

The problem (:class:`Problem`, built by :func:`build_problem`):

1. **Samples.** Every pass file's samples (any kinds: range, range_rate, doppler, azimuth,
   elevation), time-tagged at reception, with their sigma; UTC labels become SI seconds from
   the solution epoch (through TAI).
2. **Stations.** From ``--stations`` or, failing that, the pass files' metadata; WGS-84 (or
   spherical) geodetic -> ITRF -> GCRF at every reception time by IAU 2006/2000A
   (:func:`trackproc.models.measurements.station_gcrf`, the simulator's function), and the
   GCRF -> east-north-up rotation for angles.
3. **Trajectory.** :func:`trackproc.dynamics.propagator.propagate` — the Taylor (DT) engine
   with its state transition matrix, integrated in the quasi-inertial frame of the solution
   epoch (J2 about that epoch's rotation axis, as the simulator does), evaluated in GCRF by
   dense output at every emission time. One propagation per model evaluation.
4. **Measurement model.** :func:`trackproc.models.observation.evaluate`: one-way light time
   (Newton on the dense output), ``--range-rate-model`` doppler/instantaneous, station motion,
   partials through the light time, biases as modifiers. A pass file whose ``doppler_mode`` is
   ``two-way`` has its range, range-rate and Doppler samples modelled as round trips (the same
   station transmits and receives, turnaround ratio 1: range = round trip / 2, range-rate =
   mean of both legs' rates, Doppler = -2 f ρ̇ / c), with partials through both light times;
   its angles are the down leg's, as one-way.
5. **Solver.** :func:`trackproc.methods.least_squares.solve`: whitened Gauss-Newton by SVD,
   Levenberg-Marquardt damping, k-sigma editing, a-priori constraints (``--apriori-sigma``,
   ``--apriori-initial``), failures as :class:`~trackproc.errors.ProcessingError`.

Reports: the full covariance, correlation, sigmas, a-posteriori variance factor and condition
number; the state covariance in RTN (radial, along-track = N × R, cross-track = r × v / |r × v|,
an inertial rotation: the velocity block is rotated, not differentiated); residual RMS per
station and kind; optionally seed 002's comparison (Doppler-only vs extended) and the
two-stage method.

The problem (options, samples, :class:`Problem`, residual tables) is the shared OD core,
:mod:`trackproc.pipeline.od`; the a-priori and the replace/keep/decline rule are
:mod:`trackproc.methods.estimation`. This package, one responsibility per module: :mod:`.gates`
(noise model, fit, the a-priori gate), :mod:`.quality` (the ``quality`` verdict), :mod:`.seed002`
(the comparison and the two-stage method), :mod:`.result` (:func:`estimate`), :mod:`.summary`.
"""

from __future__ import annotations

from trackproc.pipeline.plotting import require_matplotlib  # noqa: F401  (re-exported for the CLI)
from trackproc.pipeline.od.options import (DOPPLER_BIAS, DOPPLER_BIAS_PER, RESIDUAL_COLUMNS, UNITS,
                                                 EstimateOptions)
from trackproc.pipeline.od.problem import Problem, build_problem
from trackproc.pipeline.estimate.gates import pass_noise
from trackproc.pipeline.estimate.quality import estimate_quality
from trackproc.pipeline.estimate.result import EstimateResult, estimate
from trackproc.pipeline.od import residual_frame
from trackproc.pipeline.estimate.summary import summary_text

__all__ = ["EstimateOptions", "Problem", "EstimateResult", "build_problem", "estimate", "estimate_quality",
           "pass_noise", "residual_frame", "summary_text", "require_matplotlib", "UNITS", "DOPPLER_BIAS",
           "DOPPLER_BIAS_PER", "RESIDUAL_COLUMNS"]

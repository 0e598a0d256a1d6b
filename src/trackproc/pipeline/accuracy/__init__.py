"""``trackproc accuracy``: sigma(t) of a predicted orbit from the initial covariance (seed 000).

Steps:

1. The initial covariance: the 6 x 6 position/velocity block of the state file's covariance
   (GCRF; extended parameters such as range biases do not move the orbit and drop out), or
   ``diag(sigma^2)`` of the state file's ``sigma``, or the command line's
   ``--sigma-position-m`` / ``--sigma-velocity-m-s`` (GCRF or RTN axes, which then take
   precedence over the file).
2. The nominal orbit and its first-order sensitivity spectra: the propagation façade
   (:func:`trackproc.dynamics.propagator.propagate_state`, Taylor/DT engine in the
   quasi-inertial frame of the epoch, ``stm=True``) over ``epoch + k * step``, k = 0 ..
   floor(span/step) (UTC labels; elapsed SI seconds through TAI).
3. The moments, by up to three methods (:mod:`trackproc.methods.accuracy`):
   ``spectral`` -- seed 000 eqs. 21-25 on the first-order random spectra (Cauchy products in
   the image domain); ``stm`` -- ``Phi P0 Phi^T``; ``monte-carlo`` -- N draws of
   ``N(x0, P0)`` propagated by the engine's batch mode in the same frame, sample moments
   accumulated about the nominal orbit (chunks of :data:`MC_CHUNK` draws).
4. Output: one row per time with the nominal state, sigma of each component in GCRF and along
   radial / along-track / cross-track axes, and with ``at_station`` sigma of range and
   range-rate (geometric partials) with the nominal range, range-rate and elevation; extra
   methods as ``stm_`` / ``mc_`` prefixed columns. On request the covariance function
   ``R(t_i, t_j)`` of every component over the grid (seed 000 eq. 25), from the first method.

Also :func:`seed_example`, the seed's worked example (eqs. 29-34) with its truncation study.
"""

from trackproc.io.time_table import FORMATS, table_bytes  # noqa: F401
from trackproc.pipeline.plotting import require_matplotlib  # noqa: F401  (re-exported for the CLI)
from trackproc.pipeline.accuracy.options import (  # noqa: F401
    COMPONENTS, DEFAULT_MONTE_CARLO, MAX_CORRELATION_TIMES, MAX_MONTE_CARLO, MAX_TIMES, MC_CHUNK, METHODS, PREFIX,
    RTN_COMPONENTS, RTN_CONVENTION, AccuracyOptions, AccuracyResult, check_options, initial_covariance)
from trackproc.pipeline.accuracy.columns import (  # noqa: F401
    consistency_checks, correlation_bytes, correlation_frame, correlation_matrices, result_meta, sigma_frame)
from trackproc.pipeline.accuracy.run import accuracy, monte_carlo, station_track  # noqa: F401
from trackproc.pipeline.accuracy.seed_example import (  # noqa: F401
    SeedExampleOptions, SeedExampleResult, seed_example, truncation_table)

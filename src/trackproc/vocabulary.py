"""The project's vocabulary, defined once: the names that appear in files, options and messages.

Every module that checks or offers one of these names (the CLI's choices, the readers'
validation, the models' ``ValueError`` messages, the batch configuration) draws it from here,
so a name cannot be spelled two ways. The names are a contract (README "Data contract",
docs/*.md): add freely, never rename. Pure data and two checks, no imports: cheap for
``--help``, and a leaf every layer may import.
"""

from __future__ import annotations

#: Measurement kinds of the canonical pass file (``kind`` column), in canonical order.
KINDS = ("range", "range_rate", "doppler", "elevation", "azimuth")
#: The same kinds in the order the estimator's reports and plots list them (azimuth first).
ESTIMATE_KIND_ORDER = ("range", "range_rate", "doppler", "azimuth", "elevation")
#: SI unit of each kind's ``value`` and ``sigma`` columns.
KIND_UNITS = {"range": "m", "range_rate": "m/s", "doppler": "Hz", "elevation": "rad", "azimuth": "rad"}
#: Kinds a two-way link changes (angles are the down leg's in both modes).
LINK_KINDS = ("range", "range_rate", "doppler")
#: Angle kinds (their residuals wrap: azimuth at 2π).
ANGLE_KINDS = ("elevation", "azimuth")

#: Link modes (the pass metadata's ``doppler_mode``, ``--mode``): the satellite transmits
#: (one-way) or transponds the station's signal back to it (two-way, round trip).
LINK_MODES = ("one-way", "two-way")
#: Range-rate models (``--range-rate-model``): ``doppler`` the derivative of the light-time
#: range (default), ``instantaneous`` Orekit's one-way ``RangeRate`` (no light-time factor).
RANGE_RATE_MODELS = ("doppler", "instantaneous")
#: Noise models of a pass's samples (``--noise``; ``auto`` chooses among the others by REML;
#: trackproc.methods.noise).
NOISE_MODELS = ("auto", "white", "ar1", "walk", "ar1+walk")

#: Force models (``--force``): the Taylor engine's two-body and J2, and ``full`` (gravity field,
#: Sun, Moon, radiation pressure, drag, relativity; trackproc.dynamics.forces, DOP853).
FORCES = ("two-body", "j2", "full")
#: The force models of the Taylor (DT) engine and the DOP853 reference (detect, refine).
TAYLOR_FORCES = ("two-body", "j2")
#: Third bodies of the full force model (``--third-body``).
THIRD_BODIES = ("sun", "moon")
#: Atmosphere models of the full force model's drag (``--atmosphere``).
ATMOSPHERES = ("harris-priester", "nrlmsis")
#: Earth figures for stations (``--earth``): WGS-84 ellipsoid or the papers' 6371 km sphere.
EARTHS = ("wgs84", "sphere")

#: Names of the six state components, in order (parameter names, covariance rows).
STATE_NAMES = ("x", "y", "z", "vx", "vy", "vz")
#: Bias parameter families (``family:KEY``) and their SI units.
BIAS_UNITS = {"range_bias": "m", "doppler_offset": "Hz", "doppler_drift": "Hz/s", "doppler_step": "Hz",
              "az_bias": "rad", "el_bias": "rad", "time_bias": "s"}
#: Parameters of constraints rather than of a measurement, and their SI units: refine's
#: circular-orbit radius (seed 004 eq. 5).
CONSTRAINT_PARAMETERS = {"r_ka": "m"}
#: Force-model parameters ``estimate`` can estimate (``--estimate-force``) and their SI units:
#: radiation-pressure and drag coefficients, a constant empirical acceleration in R, T, N, one
#: along the GCRF axes X, Y, Z and its rate of change (``_rate``: the acceleration grows as
#: ``rate * t``, t from the state's epoch; Orekit's degree-1 polynomial acceleration).
FORCE_PARAMETERS = {"cr": "1", "cd": "1", "empirical_r": "m/s^2", "empirical_t": "m/s^2", "empirical_n": "m/s^2",
                    "empirical_x": "m/s^2", "empirical_y": "m/s^2", "empirical_z": "m/s^2",
                    "empirical_x_rate": "m/s^3", "empirical_y_rate": "m/s^3", "empirical_z_rate": "m/s^3"}
#: ``--estimate-force`` names standing for several parameters (R/T/N, or GCRF X/Y/Z axes).
FORCE_PARAMETER_GROUPS = {"empirical-rtn": ("empirical_r", "empirical_t", "empirical_n"),
                          "empirical-xyz": ("empirical_x", "empirical_y", "empirical_z"),
                          "empirical-xyz-rate": ("empirical_x_rate", "empirical_y_rate", "empirical_z_rate")}
#: Doppler-bias choices (``--doppler-bias``): a transmitter frequency offset, or offset and drift.
DOPPLER_BIASES = ("offset", "offset+drift")
#: ``refine``'s Doppler-bias choices: also ``none`` (a coherent two-way link has no offset).
REFINE_DOPPLER_BIASES = ("none",) + DOPPLER_BIASES
#: estimate: auto = offset and drift for each pass of one-way Doppler (a transmitter of its own), none elsewhere
ESTIMATE_DOPPLER_BIASES = ("auto", "none") + DOPPLER_BIASES


def check_range_rate_model(model: str) -> None:
    """``ValueError`` naming the choices unless ``model`` is one of :data:`RANGE_RATE_MODELS`."""
    if model not in RANGE_RATE_MODELS:
        raise ValueError(f"unknown range-rate model {model!r}; expected one of {RANGE_RATE_MODELS}")


def check_mode(mode: str) -> None:
    """``ValueError`` naming the choices unless ``mode`` is one of :data:`LINK_MODES`."""
    if mode not in LINK_MODES:
        raise ValueError(f"unknown mode {mode!r}; expected one of {LINK_MODES}")

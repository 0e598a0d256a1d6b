"""``trackproc detect``: is the measured pass the nominal trajectory (H0) or the displaced one (H1)?

Seed 003. From a canonical pass file (elevations, and azimuths for the 3-D model) and a
nominal trajectory (NOMINAL.json), the predictions ``a_i`` (H0: displacement 0) and ``b_i``
(H1: displacement Δ*) are computed at the sample times, then the statistic S of eq. 2, its
moments (eqs. 3-4), the threshold for a chosen false-alarm probability or the equal-error
threshold, the decision and the achieved γ, α, β (:mod:`trackproc.methods.detection`).

NOMINAL.json (one JSON object; units in the names; unknown keys are an error)::

    impact_time     required  ISO 8601 UTC time T of impact (θ = θ_f) under H0
    velocity_kms | velocity_m_s, angle_deg
                    impact speed V (inertial) and flight-path angle α below the horizontal
    p_m, e [, phi_deg]
                    or the conic itself (planar only); φ (observer angle from the apse line,
                    from apogee, degrees) defaults to θ_f: the unfavourable orbit
    model           "planar" (default; seed 003 eqs. 9-11, elevation only) or "3d"
                    (DOP853 trajectory, real station, azimuth and elevation)
    displacement_m  Δ* of H1, m (default 500; ``--displacement-m`` overrides); > 0 puts the
                    observer beyond the impact point
    station         station name in the pass file (default: the only one with elevations)
    pass_id         pass to use when the station has several
    direction       "with" | "against" (object moving with / against the observer, i.e. east
                    / west for the 3-D model) | "none" (stationary observer; planar default)
    latitude_deg    observer latitude for the planar in-plane motion ω_E cos(lat)
                    (default: the station's latitude from the pass metadata)
    heading_deg     3-D only: azimuth of the impact velocity instead of with/against
    radius_m        planar Earth radius R (default 6371000)
    sigma_rad       measurement sigma, rad, when the pass's sigma column is not to be used
    tau_s           reaction time τ: samples after T - τ are not used (default 0)
    force           3-D: "two-body" (default, as the planar model) or "j2"
    earth           3-D: "wgs84" (default) or "sphere" (R = 6371 km, vertical = radial)
    kinds           3-D: ["elevation"] or ["elevation", "azimuth"] (default: both when present)

Azimuth residuals ``x - a`` and differences ``b - a`` are wrapped to (-π, π].
"""
from trackproc.vocabulary import EARTHS, FORCES, TAYLOR_FORCES  # noqa: F401  (re-exported)
from trackproc.pipeline.detect.nominal import DEG, FIELDS, MODELS, Nominal, parse_nominal, read_nominal  # noqa: F401
from trackproc.pipeline.detect.geometry import (  # noqa: F401
    StationGeometry, flight_time_s, model_3d, planar_encounter, planar_for_3d, seconds_from_impact, wrap_pi)
from trackproc.pipeline.detect.run import (  # noqa: F401
    DetectOptions, DetectResult, compare_planar, detect, result_json, select_samples)

__all__ = ["DetectOptions", "DetectResult", "Nominal", "StationGeometry", "compare_planar", "detect", "model_3d",
           "parse_nominal", "planar_encounter", "read_nominal", "result_json", "seconds_from_impact"]

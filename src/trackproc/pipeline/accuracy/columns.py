"""The output of ``trackproc accuracy`` (step 4): the one-row-per-time sigma table, its checks and
metadata, and the covariance function ``R(t_i, t_j)`` as matrices or a long table.
"""

from __future__ import annotations

import numpy as np
import pandas as pd

from trackproc import __version__
from trackproc.constants import force_model_constants
from trackproc.io.jsonutil import dumps
from trackproc.io.passfile import iso_times
from trackproc.io.statefile import FORCE_LABELS
from trackproc.io.time_table import table_bytes
from trackproc.isotime import iso_utc
from trackproc.methods import accuracy as ac
from trackproc.pipeline.accuracy.options import COMPONENTS, PREFIX, RTN_COMPONENTS, RTN_CONVENTION, AccuracyResult
from trackproc.types import STATE_PARAMETERS


def _columns(prefix, cov, rtn, obs) -> dict:
    cols = {}
    sig = ac.sigmas(cov)
    for k, (name, unit, _) in enumerate(COMPONENTS):
        cols[f"{prefix}sigma_{name}_{unit}"] = sig[:, k]
    sig = ac.sigmas(rtn)
    for k, (name, unit, _) in enumerate(RTN_COMPONENTS):
        cols[f"{prefix}sigma_{name}_{unit}"] = sig[:, k]
    cols[f"{prefix}sigma_position_m"] = np.sqrt(np.clip(np.trace(cov[:, :3, :3], axis1=1, axis2=2), 0, None))
    cols[f"{prefix}sigma_velocity_m_s"] = np.sqrt(np.clip(np.trace(cov[:, 3:, 3:], axis1=1, axis2=2), 0, None))
    if obs is not None:
        so = ac.sigmas(obs)
        cols[f"{prefix}sigma_range_m"] = so[:, 0]
        cols[f"{prefix}sigma_range_rate_m_s"] = so[:, 1]
    return cols


def sigma_frame(times, t, nominal, covs, rtn, obs, track, options, mc) -> pd.DataFrame:
    # elapsed time to the nanosecond the times carry (not 600.0000000000026 from the JD arithmetic)
    cols = {"time": pd.DatetimeIndex(times).tz_localize("UTC"), "elapsed_s": np.round(t, 9)}
    for k, (name, unit, _) in enumerate(COMPONENTS):
        cols[f"{name}_{unit}"] = nominal[:, k]
    first = options.methods[0]
    cols.update(_columns("", covs[first], rtn[first], obs.get(first)))
    if track is not None:
        cols["range_m"] = track["range_m"]
        cols["range_rate_m_s"] = track["range_rate_m_s"]
        cols["elevation_deg"] = np.degrees(track["elevation_rad"])
    for method in options.methods[1:]:
        cols.update(_columns(PREFIX[method], covs[method], rtn[method], obs.get(method)))
    if mc is not None:
        prefix = "" if first == "monte-carlo" else "mc_"
        cols[f"{prefix}mean_offset_position_m"] = np.linalg.norm(mc["mean_dev"][:, :3], axis=-1)
        cols[f"{prefix}mean_offset_velocity_m_s"] = np.linalg.norm(mc["mean_dev"][:, 3:], axis=-1)
    return pd.DataFrame(cols)


def consistency_checks(covs, rtn, n_samples) -> dict:
    """Cross-checks between the methods that ran: relative sigma differences and MC z-scores."""
    out = {}

    def diag(c, r):
        return np.concatenate([np.diagonal(c, axis1=1, axis2=2), np.diagonal(r, axis1=1, axis2=2)], -1)

    if "spectral" in covs and "stm" in covs:
        a, b = np.sqrt(np.clip(diag(covs["spectral"], rtn["spectral"]), 0, None)), \
            np.sqrt(np.clip(diag(covs["stm"], rtn["stm"]), 0, None))
        ok = b > 0
        out["spectral_vs_stm_max_relative_sigma_difference"] = float(np.max(np.abs(a - b)[ok] / b[ok])) if ok.any() \
            else 0.0
    if "monte-carlo" in covs:
        lin = "spectral" if "spectral" in covs else "stm" if "stm" in covs else None
        bounds = ac.monte_carlo_bounds(n_samples)
        out["monte_carlo_variance_relative_sd"] = bounds["variance_relative_sd"]
        if lin is not None:
            v_mc = diag(covs["monte-carlo"], rtn["monte-carlo"])
            v_lin = diag(covs[lin], rtn[lin])
            ok = v_lin > 0
            z = (v_mc[ok] / v_lin[ok] - 1.0) / bounds["variance_relative_sd"]
            out["monte_carlo_vs_linear_max_abs_z"] = float(np.max(np.abs(z))) if z.size else 0.0
            out["monte_carlo_vs_linear_reference"] = lin
    return out


def correlation_matrices(method, factor, mc, nominal) -> dict:
    """Covariance function R(t_i, t_j) of every component, (M, M) each (seed 000 eq. 25)."""
    names = [c[0] for c in COMPONENTS] + [c[0] for c in RTN_COMPONENTS]
    if method == "monte-carlo":
        cross = mc["cross"]                                                   # (12, M, M)
    else:
        f = np.concatenate([factor, ac.rtn_jacobian(nominal[:, :3], nominal[:, 3:]) @ factor], axis=1)  # (M, 12, k)
        cross = np.einsum("mck,nck->cmn", f, f)
    return {"method": method, "components": names, "cov": {n: cross[i] for i, n in enumerate(names)}}


def result_meta(state, options, traj, cov0, cov_label, checks, eop, track, mc) -> dict:
    units = {"time": "UTC", "elapsed_s": "s"}
    meta = {
        "schema_version": 1,
        "product": "trackproc accuracy",
        "time_scale": "UTC",
        "frame": "GCRF",
        "epoch": iso_utc(state.epoch),
        "state_source": state.source,
        "span_s": float(options.span_s),
        "step_s": float(options.step_s),
        "force_model": (options.force_model.label() if options.force_model is not None
                        else FORCE_LABELS.get(options.force, options.force)),
        "constants": (options.force_model.describe() if options.force_model is not None
                      else force_model_constants(options.force)),
        "earth_orientation": getattr(eop, "source", None) or "none (UT1-UTC = 0, no polar motion)",
        "methods": list(options.methods),
        "unprefixed_method": options.methods[0],
        "column_prefixes": {m: ("" if m == options.methods[0] else PREFIX[m]) for m in options.methods},
        "initial_covariance": {"source": cov_label, "sigma": np.sqrt(np.clip(np.diag(cov0), 0, None)).tolist(),
                               "matrix": cov0.tolist(), "parameters": list(STATE_PARAMETERS)},
        "rtn_axes": RTN_CONVENTION,
        "first_order": ("spectral (seed 000 eqs. 21-25 on the engine's first-order sensitivity spectra) and stm "
                        "(Phi P0 Phi^T) are first order in the initial errors and give the same numbers; "
                        "Monte Carlo keeps every nonlinearity"),
        "propagator": {"engine": "adaptive Taylor (DT), trackproc.dynamics.taylor via dynamics.propagator",
                       "frame": "quasi-inertial frame of the epoch (J2 about its rotation axis)",
                       "order": traj.order, "tol": traj.tol, "steps": traj.n_steps},
        "checks": checks,
        "trackproc_version": __version__,
        "units": units,
    }
    if mc is not None:
        meta["monte_carlo"] = {"n_samples": mc["n"], "seed": mc["seed"], **ac.monte_carlo_bounds(mc["n"]),
                               "note": "sd of the sample variance of N Gaussian draws: sqrt(2/(N-1)) relative"}
    if track is not None:
        st = track["station"]
        meta["station"] = {"name": options.at_station, "lat_deg": float(st.lat_deg), "lon_deg": float(st.lon_deg),
                           "height_m": float(st.height_m), "earth": options.earth,
                           "model": "geometric range |r - r_st| and range-rate u.(v - v_st) at the sample time "
                                    "(no light time; partials change by v/c ~ 3e-5 relative)"}
    return meta


def correlation_frame(result: AccuracyResult) -> pd.DataFrame:
    """The covariance function as a long table: one row per pair (t_i, t_j), all pairs.

    Columns ``time_1, time_2, elapsed_1_s, elapsed_2_s``, then per component ``cov_<c>_<unit^2>``
    (``cov_x_m2``, ``cov_vx_m2_s2``, ``cov_radial_m2``, ...) and ``corr_<c>``
    (``R(t_i, t_j) / sqrt(D(t_i) D(t_j))``).
    """
    c = result.correlation
    m = result.elapsed_s.size
    i, j = np.meshgrid(np.arange(m), np.arange(m), indexing="ij")
    i, j = i.ravel(), j.ravel()
    t = pd.DatetimeIndex(result.times).tz_localize("UTC")
    cols = {"time_1": t[i], "time_2": t[j], "elapsed_1_s": result.elapsed_s[i], "elapsed_2_s": result.elapsed_s[j]}
    units = {name: u for name, u, _ in COMPONENTS + RTN_COMPONENTS}
    for name in c["components"]:
        cov = c["cov"][name]
        unit = "m2" if units[name] == "m" else "m2_s2"
        cols[f"cov_{name}_{unit}"] = cov[i, j]
        d = np.diagonal(cov)
        cols[f"corr_{name}"] = ac.correlation_coefficients(cov, d, d)[i, j]
    return pd.DataFrame(cols)


def correlation_bytes(result: AccuracyResult, fmt: str) -> bytes:
    """``--correlation FILE``: JSON matrices, or the long table of :func:`correlation_frame`."""
    fmt = getattr(fmt, "value", fmt)
    c = result.correlation
    meta = dict(result.meta)
    meta["correlation"] = {"method": c["method"],
                           "definition": "R(t_i, t_j) = E[dx(t_i) dx(t_j)] of each component (seed 000 eq. 25); "
                                         "corr = R / sqrt(D(t_i) D(t_j))"}
    if fmt == "json":
        units = {name: u for name, u, _ in COMPONENTS + RTN_COMPONENTS}
        cov = {f"{n}_{'m2' if units[n] == 'm' else 'm2_s2'}": c["cov"][n] for n in c["components"]}
        corr = {}
        for n in c["components"]:
            d = np.diagonal(c["cov"][n])
            corr[n] = ac.correlation_coefficients(c["cov"][n], d, d)
        t = pd.Series(pd.DatetimeIndex(result.times).tz_localize("UTC"))
        return dumps({"metadata": meta, "times": list(iso_times(t)), "elapsed_s": result.elapsed_s,
                      "covariance": cov, "correlation": corr}).encode("utf-8")
    return table_bytes(correlation_frame(result), meta, fmt)

"""Figures of ``trackproc accuracy``: sigma(t) by method (like seed 000 Fig. 1-2) and the seed's
worked example with its truncation study."""

from __future__ import annotations

import math

import numpy as np

from trackproc.methods import accuracy as ac
from trackproc.pipeline.accuracy import AccuracyResult, SeedExampleResult
from trackproc.report.plots import encode, legend_outside, pyplot


def _png(fig) -> bytes:
    """PNG at 110 dpi (the accuracy figures' resolution since they were written)."""
    return encode(fig, dpi=110)


def plot_bytes(result: AccuracyResult) -> bytes:
    """PNG: sigma(t) of position and velocity along radial / along-track / cross-track (and of
    range and range-rate at the station), every method that ran (like seed 000 Fig. 1-2)."""
    plt = pyplot()
    f = result.frame
    methods = result.meta["methods"]
    prefixes = result.meta["column_prefixes"]
    hours = f["elapsed_s"].to_numpy() / 3600.0
    panels = [("position", [("radial", "m"), ("along", "m"), ("cross", "m")], "sigma, m"),
              ("velocity", [("v_radial", "m_s"), ("v_along", "m_s"), ("v_cross", "m_s")], "sigma, m/s")]
    if "sigma_range_m" in f.columns:
        # one unit per panel; the station's sigmas only while the satellite is above its horizon
        name = result.meta["station"]["name"]
        panels.append((f"station {name}: range (while visible)", [("range", "m")], "sigma, m"))
        panels.append((f"station {name}: range-rate (while visible)", [("range_rate", "m_s")], "sigma, m/s"))
    visible = (f["elevation_deg"].to_numpy() > 0.0) if "elevation_deg" in f.columns else np.ones(len(f), bool)
    fig, axes = plt.subplots(len(panels), 1, figsize=(9, 3.4 * len(panels)), sharex=True, squeeze=False)
    styles = {"spectral": dict(ls="-", lw=1.6), "stm": dict(ls="--", lw=1.2), "monte-carlo": dict(ls="", marker=".")}
    colors = ["C0", "C1", "C2"]
    for ax, (title, comps, ylabel) in zip(axes[:, 0], panels):
        for k, (name, unit) in enumerate(comps):
            for method in methods:
                col = f"{prefixes[method]}sigma_{name}_{unit}"
                if col not in f.columns:
                    continue
                label = f"{name} ({method})"
                values = f[col].to_numpy(dtype=float)
                if title.startswith("station"):
                    values = np.where(visible, values, np.nan)   # below the horizon: no measurement
                ax.plot(hours, values, color=colors[k], label=label, **styles[method])
        ax.set_yscale("log")
        ax.set_ylabel(ylabel)
        ax.set_title(f"{title}: 1-sigma of the predicted state", fontsize=10)
        ax.grid(True, which="both", alpha=0.3)
        legend_outside(ax)
    axes[-1, 0].set_xlabel(f"hours since {result.meta['epoch']}")
    fig.suptitle(f"trackproc accuracy: {result.meta['force_model']}, {result.meta['initial_covariance']['source']}",
                 fontsize=9)
    fig.tight_layout()
    return _png(fig)


def seed_example_plot_bytes(result: SeedExampleResult) -> bytes:
    """PNG like seed 000 Fig. 1-2 (sigma_x(t) for fixed position error and velocity errors in the
    ratio 2, and the converse) plus the truncation study (4 and 6 discretes vs enough)."""
    plt = pyplot()
    o, n = result.options, result.n_rad_s
    f = result.frame
    t = f["elapsed_s"].to_numpy()
    tt = np.linspace(0.0, t[-1], 600)
    fig, axes = plt.subplots(2, 2, figsize=(12, 8.5))
    ax = axes[0, 0]
    for k in (0.5, 1.0, 2.0):
        ax.plot(tt, np.sqrt(ac.seed000_variance_exact(tt, o.sigma_position_m, k * o.sigma_velocity_m_s, n)),
                label=f"sigma_v2 = {k * o.sigma_velocity_m_s:g} m/s")
    ax.set_title(f"Fig. 1: sigma_v1 = {o.sigma_position_m:g} m fixed, velocity errors in ratio 2", fontsize=10)
    ax = axes[0, 1]
    for k in (0.5, 1.0, 2.0):
        ax.plot(tt, np.sqrt(ac.seed000_variance_exact(tt, k * o.sigma_position_m, o.sigma_velocity_m_s, n)),
                label=f"sigma_v1 = {k * o.sigma_position_m:g} m")
    ax.set_title(f"Fig. 2: sigma_v2 = {o.sigma_velocity_m_s:g} m/s fixed, position errors in ratio 2", fontsize=10)
    for ax in axes[0]:
        ax.set_xlabel("extrapolation time t, s")
        ax.set_ylabel("sigma_x(t), m")
        ax.grid(True, alpha=0.3)
        legend_outside(ax, fontsize=8)
    ax = axes[1, 0]
    ax.plot(t, f["sigma_x_m"], "k-", lw=2, label="exact")
    ax.plot(t, f["sigma_x_spectral_m"], ls=":", color="gold", lw=2,
            label=f"spectral, {result.meta['spectral']['discretes']} discretes, restarted")
    for nd in o.discretes:
        ax.plot(t, f[f"sigma_x_n{nd}_m"], label=f"{nd} discretes (H = t)")
    top = float(np.max(f["sigma_x_m"])) * 3
    ax.set_ylim(0, top)
    ax.set_title("sigma_x(t) from truncated spectra", fontsize=10)
    ax = axes[1, 1]
    floor = 1e-17
    for nd in o.discretes:
        ax.semilogy(t[1:], np.maximum(np.abs(f[f"rel_err_var_x_n{nd}"].to_numpy()[1:]), floor),
                    label=f"{nd} discretes (H = t)")
    ax.semilogy(t[1:], np.maximum(np.abs(f["rel_err_var_x_spectral"].to_numpy()[1:]), floor), "k",
                label="enough discretes")
    ax.set_title("|D_x - exact| / exact", fontsize=10)
    for ax in axes[1]:
        ax.set_xlabel("extrapolation time t, s")
        ax.grid(True, which="both", alpha=0.3)
        legend_outside(ax, fontsize=8)
    axes[1, 0].set_ylabel("sigma_x(t), m")
    fig.suptitle(f"seed 000 example: r = {o.radius_m / 1e3:g} km, n = {n:.4e} rad/s, "
                 f"period {2 * math.pi / n:.0f} s", fontsize=10)
    fig.tight_layout()
    return _png(fig)

"""Figures a flight-dynamics engineer would put in a report (issue 16): residuals per kind with
units and RMS per pass, angles in degrees.

Each function takes plain data (pandas frames, numpy arrays) and returns the encoded file (PNG, or
a multi-page PDF where a figure per pass is asked for).
"""

from __future__ import annotations

import io
import textwrap
from pathlib import Path

import numpy as np

from trackproc.pipeline.plotting import require_matplotlib

#: How each measurement kind is shown: (label, unit, factor from SI).
DISPLAY = {"range": ("range", "m", 1.0), "range_rate": ("range-rate", "m/s", 1.0),
           "doppler": ("Doppler", "Hz", 1.0), "elevation": ("elevation", "deg", 180.0 / np.pi),
           "azimuth": ("azimuth", "deg", 180.0 / np.pi)}


def pyplot():
    """matplotlib's pyplot on the file-only Agg backend (a clear error when the extra is missing)."""
    require_matplotlib()
    import matplotlib  # optional (the plot extra), ~0.3 s with pyplot

    matplotlib.use("Agg", force=True)
    import matplotlib.pyplot as plt

    return plt


#: Called with every figure just before it is saved (the tests check its layout here).
FIGURE_CHECKS: list = []


def encode(fig, fmt: str = "png", dpi: int = 100, tight: bool = True) -> bytes:
    """The figure as ``fmt`` bytes; ``tight``: the saved area grows to every artist (legends placed
    outside the axes, rotated tick labels), so nothing is clipped."""
    plt = pyplot()
    for check in FIGURE_CHECKS:
        check(fig)
    buffer = io.BytesIO()
    fig.savefig(buffer, format=fmt, dpi=dpi, **({"bbox_inches": "tight", "pad_inches": 0.1} if tight else {}))
    plt.close(fig)
    return buffer.getvalue()


def legend_outside(ax, handles=None, **kw):
    """The legend of ``ax`` to the right of its axes, off the data (``tight_layout`` and the tight
    save make room for it); nothing when there is nothing to label."""
    handles, labels = (ax.get_legend_handles_labels() if handles is None
                       else (handles, [h.get_label() for h in handles]))
    if not handles:
        return None
    kw.setdefault("fontsize", 7)
    return ax.legend(handles, labels, loc="upper left", bbox_to_anchor=(1.01, 1.0), borderaxespad=0.0, **kw)


def break_gaps(t, *series, factor: float = 4.0):
    """``t`` and ``series`` with a NaN inserted wherever consecutive samples are more than
    ``factor`` times the median step apart, so a line drawn through them breaks at the data
    gaps instead of bridging them."""
    t = np.asarray(t, dtype=float)
    series = [np.asarray(y, dtype=float) for y in series]
    if t.size < 3:
        return (t, *series)
    step = np.diff(t)
    positive = step[step > 0]
    if not positive.size:
        return (t, *series)
    cut = np.nonzero(step > factor * np.median(positive))[0] + 1
    return (np.insert(t, cut, np.nan), *(np.insert(y, cut, np.nan) for y in series))


def rms_by_pass(frame) -> dict:
    """{(kind, pass_id): (rms in display units, samples kept)} of the residuals not edited."""
    out = {}
    kept = frame[~frame["edited"].to_numpy(dtype=bool)]
    for (kind, pass_id), group in kept.groupby(["kind", "pass_id"], sort=True):
        factor = DISPLAY.get(kind, (kind, "", 1.0))[2]
        r = group["residual"].to_numpy(dtype=float) * factor
        out[(kind, pass_id)] = (float(np.sqrt(np.mean(r * r))) if r.size else float("nan"), int(r.size))
    return out


def residuals_png(frame) -> bytes:
    """Residuals (observed - computed) against time: one panel per measurement kind in its own unit
    (degrees for angles), one colour per station, edited samples as red crosses (clipped to the
    panel), and each pass's RMS in the legend."""
    plt = pyplot()
    kinds = [k for k in DISPLAY if (frame["kind"] == k).any()] + sorted(set(frame["kind"]) - set(DISPLAY))
    rms = rms_by_pass(frame)
    fig, axes = plt.subplots(len(kinds), 1, figsize=(11, 2.9 * len(kinds)), squeeze=False, sharex=True)
    t0 = frame["time"].min()
    for ax, kind in zip(axes[:, 0], kinds):
        label, unit, factor = DISPLAY.get(kind, (kind, "", 1.0))
        sub = frame[frame["kind"] == kind]
        hours = (sub["time"] - t0).dt.total_seconds().to_numpy() / 3600.0
        residual = sub["residual"].to_numpy(dtype=float) * factor
        edited = sub["edited"].to_numpy(dtype=bool)
        for station in sorted(sub["station"].unique()):
            m = (sub["station"] == station).to_numpy() & ~edited
            passes = sorted(sub.loc[m, "pass_id"].unique())
            text = "; ".join(f"{p} {rms[(kind, p)][0]:.3g}" for p in passes if (kind, p) in rms)
            ax.plot(hours[m], residual[m], ".", ms=2, label=f"{station}: RMS {text} {unit}")
        span = 5.0 * max(np.sqrt(np.mean(residual[~edited] ** 2)) if (~edited).any() else 1.0, 1e-300)
        if edited.any():
            ax.plot(hours[edited], np.clip(residual[edited], -span, span), "x", ms=4, color="red",
                    label=f"edited ({int(edited.sum())})")
        ax.axhline(0.0, color="0.3", lw=0.6)
        ax.set_ylim(-span, span)
        ax.set_ylabel(f"{label} residual [{unit}]")
        legend_outside(ax, markerscale=3)
    axes[-1, 0].set_xlabel(f"hours since {t0.isoformat()}")
    fig.suptitle("residuals, observed - computed (RMS per pass in the legend)", fontsize=10)
    fig.tight_layout()
    return encode(fig)


RTN = (("radial_m", "R", "m"), ("along_m", "T", "m"), ("cross_m", "N", "m"),
       ("radial_m_s", "R", "m/s"), ("along_m_s", "T", "m/s"), ("cross_m_s", "N", "m/s"))


def refine_png(residuals, diagnostics: dict) -> bytes:
    """``refine --plot``: the pass's data and the refined orbit's model through it, the residuals
    with their RMS, and what the pass can and cannot see: the correction (refined - stale) split
    into its seen and unseen parts against the posterior and a-priori sigmas, per radial /
    along-track / cross-track component."""
    plt = pyplot()
    frame = residuals.sort_values("time")
    kind = str(frame["kind"].iloc[0])
    label, unit, factor = DISPLAY.get(kind, (kind, "", 1.0))
    t0 = frame["time"].min()
    t = (frame["time"] - t0).dt.total_seconds().to_numpy()
    edited = frame["edited"].to_numpy(dtype=bool)
    observed = frame["observed"].to_numpy(dtype=float) * factor
    computed = frame["computed"].to_numpy(dtype=float) * factor
    residual = frame["residual"].to_numpy(dtype=float) * factor
    obs = diagnostics.get("observability") or {}
    fig = plt.figure(figsize=(11, 10))
    grid = fig.add_gridspec(3, 2, height_ratios=[1.2, 1.0, 1.1])
    ax = fig.add_subplot(grid[0, :])
    ax.plot(t[~edited], observed[~edited], ".", ms=2, color="0.4", label="data")
    if edited.any():
        ax.plot(t[edited], observed[edited], "x", ms=4, color="red", label=f"edited ({int(edited.sum())})")
    ax.plot(*break_gaps(t, computed), "-", lw=1.2, color="C0", label="refined orbit (model)")
    traverse = (diagnostics.get("traverse") or {}).get("epoch")
    if traverse:
        import pandas as pd  # start-up: pandas (~0.3 s) only for this figure

        tt = (pd.Timestamp(traverse) - t0).total_seconds()
        ax.axvline(tt, color="green", lw=0.8, label="traverse point")
    ax.set_ylabel(f"{label} [{unit}]")
    ax.set_title(f"{label} of the pass and the refined orbit", fontsize=10)
    legend_outside(ax)
    ax = fig.add_subplot(grid[1, :], sharex=ax)
    rms = float(np.sqrt(np.mean(residual[~edited] ** 2))) if (~edited).any() else float("nan")
    span = 5 * rms if np.isfinite(rms) and rms > 0 else 1.0
    ax.plot(t[~edited], residual[~edited], ".", ms=2, color="C0")
    if edited.any():
        ax.plot(t[edited], np.clip(residual[edited], -span, span), "x", ms=4, color="red")
    ax.axhline(0.0, color="0.3", lw=0.6)
    ax.set_ylim(-span, span)
    ax.set_ylabel(f"residual [{unit}]")
    ax.set_xlabel(f"s since {t0.isoformat()}")
    ax.set_title(f"residuals, RMS {rms:.3g} {unit}", fontsize=10)
    correction = obs.get("correction_rtn") or {}
    posterior, reference = obs.get("posterior_sigma_rtn") or {}, obs.get("reference_sigma_rtn") or {}
    for col, (unit_rtn, keys) in enumerate((("m", RTN[:3]), ("m/s", RTN[3:]))):
        ax = fig.add_subplot(grid[2, col])
        x = np.arange(3)
        seen = [abs((correction.get("seen") or {}).get(k, np.nan)) for k, _, _ in keys]
        unseen = [abs((correction.get("unseen") or {}).get(k, np.nan)) for k, _, _ in keys]
        ax.bar(x - 0.2, seen, 0.4, label="|correction| the pass sees", color="C0")
        ax.bar(x + 0.2, unseen, 0.4, label="|correction| it cannot see (a-priori)", color="C1")
        ax.plot(x, [posterior.get(k, np.nan) for k, _, _ in keys], "k_", ms=22, mew=2, label="posterior sigma")
        ax.plot(x, [reference.get(k, np.nan) for k, _, _ in keys], "_", color="0.6", ms=22, mew=2,
                label="a-priori sigma")
        ax.set_xticks(x, [f"{name} [{unit_rtn}]" for _, name, _ in keys])
        ax.set_yscale("log")
        ax.set_title(("position" if col == 0 else "velocity") + ": refined - stale", fontsize=10)
        if col == 1:  # the same four entries for both panels: once, right of the velocity panel
            legend_outside(ax)
    unseen_text = "; ".join(obs.get("unobservable") or []) or "none"
    fig.suptitle(textwrap.fill(f"trackproc refine - not seen by the pass: {unseen_text}", 110), fontsize=10)
    fig.tight_layout()
    return encode(fig)


def detect_png(samples: dict, document: dict) -> bytes:
    """``detect --plot`` (seed 003): per angle kind, the measured minus the nominal (H0) angle and the
    displaced (H1) minus the nominal, in degrees against the time to impact, with the 1-sigma band;
    then the statistic S against its normal laws under H0 and H1 and the threshold."""
    plt = pyplot()
    kinds = [k for k in ("elevation", "azimuth") if (samples["kinds"] == k).any()]
    fig, axes = plt.subplots(len(kinds) + 1, 1, figsize=(10, 3.2 * (len(kinds) + 1)), squeeze=False)
    deg = 180.0 / np.pi
    for ax, kind in zip(axes[:-1, 0], kinds):
        m = samples["kinds"] == kind
        s = samples["s"][m]
        ax.fill_between(s, -samples["sigma"][m] * deg, samples["sigma"][m] * deg, color="0.85", label="±1 sigma")
        ax.plot(s, (samples["x"][m] - samples["a"][m]) * deg, ".", ms=2, color="C0", label="measured - H0")
        ax.plot(s, (samples["b"][m] - samples["a"][m]) * deg, "-", color="C3",
                label=f"H1 - H0 ({document['displacement_m']:g} m displacement)")
        ax.axhline(0.0, color="0.3", lw=0.6)
        ax.set_ylabel(f"{kind} [deg]")
        ax.set_xlabel("s from the nominal impact time")
        legend_outside(ax)
    ax = axes[-1, 0]
    st = document["statistic"]
    std = st["std"]
    lo = min(st["mean_h0"], st["S"]) - 4 * std
    hi = max(st["mean_h1"], st["S"]) + 4 * std
    grid = np.linspace(lo, hi, 400)
    for mean, name, colour in ((st["mean_h0"], "H0", "C0"), (st["mean_h1"], "H1", "C3")):
        ax.plot(grid, np.exp(-0.5 * ((grid - mean) / std) ** 2) / (std * np.sqrt(2 * np.pi)), color=colour,
                label=f"S under {name}")
    ax.axvline(document["threshold"], color="k", ls="--", lw=1, label="threshold")
    ax.axvline(st["S"], color="green", lw=2, label=f"S observed -> {document['decision']}")
    ax.set_xlabel("S [rad^2]")
    ax.set_ylabel("probability density [1/rad^2]")
    ax.set_title(f"false alarm {document['false_alarm_probability']:.3g}, miss {document['miss_probability']:.3g}, "
                 f"gamma {document['gamma']:.3g}", fontsize=10)
    legend_outside(ax)
    fig.suptitle(f"trackproc detect: {document['station']} {document['pass_id']}", fontsize=10)
    fig.tight_layout()
    return encode(fig)


def smooth_figure(fit_item, values):
    """One pass and kind of ``smooth``: the data (rejected samples marked), the fitted curve, the TCA,
    and the residuals with their RMS; angles in degrees."""
    plt = pyplot()
    f = fit_item
    label, unit, factor = DISPLAY.get(f.kind, (f.kind, "", 1.0))
    values = np.asarray(values, float) * factor
    fig, (ax_data, ax_res) = plt.subplots(1, 2, figsize=(13, 3.6), gridspec_kw={"width_ratios": [3, 2]})
    title = f"{f.label}  [{f.status}]"
    if f.fit is None:
        ax_data.plot(f.t_s, values, ".", ms=2, color="0.5")
        ax_data.set_title(f"{title}: {f.error}", fontsize=9)
        ax_res.set_axis_off()
    else:
        used = f.fit.used
        ax_data.plot(f.t_s[used], values[used], ".", ms=2, label="used")
        if (~used).any():
            ax_data.plot(f.t_s[~used], values[~used], "x", ms=4, color="red", label=f"rejected ({int((~used).sum())})")
        grid = np.linspace(*f.fit.domain_s, 600)
        ax_data.plot(grid, f.fit(grid) * factor, "-", color="black", lw=1, label=f"degree {f.fit.degree}")
        lo, hi = np.nanmin(values), np.nanmax(values)
        pad = 0.1 * (hi - lo) if hi > lo else 1.0
        ax_data.set_ylim(lo - pad, hi + pad)
        if f.tca is not None:
            ax_data.axvline(f.tca.t_s, color="green", lw=0.8, label=f"TCA ±{f.tca.sigma_s:.3g} s")
        ax_data.set_title(title + (f"  {', '.join(f.warnings)}" if f.warnings else ""), fontsize=9)
        # right of the residual panel, off both panels' data
        legend_outside(ax_res, handles=ax_data.get_legend_handles_labels()[0])
        residual = f.fit.residual * factor
        ax_res.plot(f.t_s[used], residual[used], ".", ms=2)
        if (~used).any():
            ax_res.plot(f.t_s[~used], residual[~used], "x", ms=4, color="red")
        span = 6 * max(f.fit.rms * factor, 1e-300)
        ax_res.set_ylim(-span, span)
        ax_res.set_title(f"residual, RMS {f.fit.rms * factor:.3g} {unit}", fontsize=9)
        ax_res.set_xlabel("s from the first sample of the pass")
    ax_data.set_ylabel(f"{label} [{unit}]")
    ax_data.set_xlabel("s from the first sample of the pass")
    fig.tight_layout()
    return fig


def smooth_plots(result, path: str) -> dict:
    """``smooth --plot``: one figure per pass and kind. ``*.pdf``: one page each in one file; a PNG
    path with one fit: that figure; with several: ``NAME-<pass>-<kind>.png`` beside it (a
    1170 x 6912 px stack is unreadable). Returns {file name: bytes} to write."""
    plt = pyplot()
    frame = result.samples.frame
    fits = list(result.fits)
    target = Path(path)
    if target.suffix.lower() == ".pdf":
        from matplotlib.backends.backend_pdf import PdfPages  # optional: the plot extra

        buffer = io.BytesIO()
        with PdfPages(buffer) as pdf:
            for f in fits:
                fig = smooth_figure(f, frame["value"].to_numpy()[f.rows])
                pdf.savefig(fig)
                plt.close(fig)
        return {str(target): buffer.getvalue()}
    if len(fits) == 1:
        return {str(target): encode(smooth_figure(fits[0], frame["value"].to_numpy()[fits[0].rows]))}
    out = {}
    for f in fits:
        name = f"{target.stem}-{f.label}".replace(" ", "-").replace("/", "-")
        out[str(target.with_name(name + (target.suffix or ".png")))] = encode(
            smooth_figure(f, frame["value"].to_numpy()[f.rows]))
    return out


def filter_png(innovations, sigmas) -> bytes:
    """``filter --plot``: per measurement kind, the innovations (observed - predicted before the
    update) in its own unit (degrees for angles) with their ±3σ band, ±3 √S with
    ``S = h P hᵀ + r`` the innovation variance (Tapley, Schutz & Born 2004 eq. 4.7.7's denominator),
    edited samples as red crosses; then the 1σ position uncertainty along radial, along-track and
    cross-track over time (filtered, and smoothed when present), on a log scale.

    ``innovations``: the filter's innovation table; ``sigmas``: one row per step and solution with
    ``time`` (UTC), ``solution``, ``radial_m``, ``along_m``, ``cross_m``."""
    import pandas as pd  # start-up: pandas (~0.3 s) only for this figure

    plt = pyplot()
    frame = innovations
    kinds = [k for k in DISPLAY if (frame["kind"] == k).any()] + sorted(set(frame["kind"]) - set(DISPLAY))
    fig, axes = plt.subplots(len(kinds) + 1, 1, figsize=(11, 2.9 * (len(kinds) + 1)), squeeze=False, sharex=True)
    times = pd.DatetimeIndex(pd.to_datetime(sigmas["time"], utc=True)) if len(sigmas) else frame["time"]
    t0 = min(frame["time"].min(), times.min())
    for ax, kind in zip(axes[:-1, 0], kinds):
        label, unit, factor = DISPLAY.get(kind, (kind, "", 1.0))
        sub = frame[frame["kind"] == kind]
        hours = (sub["time"] - t0).dt.total_seconds().to_numpy() / 3600.0
        nu = sub["innovation"].to_numpy(dtype=float) * factor
        band = 3.0 * sub["innovation_sigma"].to_numpy(dtype=float) * factor
        edited = sub["edited"].to_numpy(dtype=bool)
        for station in sorted(sub["station"].unique()):
            m = (sub["station"] == station).to_numpy() & ~edited
            ax.plot(hours[m], nu[m], ".", ms=2, label=f"{station} ({int(m.sum())})")
        h, b = break_gaps(hours, band)
        ax.plot(h, b, "-", lw=0.8, color="k", label="±3σ (3 √S)")
        ax.plot(h, -b, "-", lw=0.8, color="k")
        kept_band = band[~edited] if (~edited).any() else band
        span = 1.5 * max(np.nanpercentile(kept_band, 95) if kept_band.size else 1.0, 1e-300)
        if edited.any():
            ax.plot(hours[edited], np.clip(nu[edited], -span, span), "x", ms=4, color="red",
                    label=f"edited ({int(edited.sum())})")
        ax.axhline(0.0, color="0.3", lw=0.6)
        ax.set_ylim(-span, span)
        ax.set_ylabel(f"{label} innovation [{unit}]")
        legend_outside(ax, markerscale=3)
    ax = axes[-1, 0]
    hours = (times - t0).total_seconds().to_numpy() / 3600.0
    for solution, style in (("filtered", "-"), ("smoothed", "--")):
        m = (sigmas["solution"] == solution).to_numpy() if len(sigmas) else np.zeros(0, bool)
        if not m.any():
            continue
        for (column, name, _), colour in zip(RTN[:3], ("C0", "C1", "C2")):
            ax.plot(*break_gaps(hours[m], sigmas[column].to_numpy(dtype=float)[m]), style, lw=1.0, color=colour,
                    label=f"{name} ({solution})")
    ax.set_yscale("log")
    ax.set_ylabel("position 1σ [m]")
    legend_outside(ax)
    axes[-1, 0].set_xlabel(f"hours since {t0.isoformat()}")
    fig.suptitle("trackproc filter: innovations with their ±3σ bands; position sigmas radial (R), "
                 "along-track (T), cross-track (N)", fontsize=10)
    fig.tight_layout()
    return encode(fig)

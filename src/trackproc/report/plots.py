"""Figures a flight-dynamics engineer would put in a report (issue 16): residuals per kind with
units and RMS per pass, angles in degrees.

Each function takes plain data (pandas frames, numpy arrays) and returns the encoded file (PNG, or
a multi-page PDF where a figure per pass is asked for).
"""

from __future__ import annotations

import io

import numpy as np

#: How each measurement kind is shown: (label, unit, factor from SI).
DISPLAY = {"range": ("range", "m", 1.0), "range_rate": ("range-rate", "m/s", 1.0),
           "doppler": ("Doppler", "Hz", 1.0), "elevation": ("elevation", "deg", 180.0 / np.pi),
           "azimuth": ("azimuth", "deg", 180.0 / np.pi)}


def pyplot():
    """matplotlib's pyplot on the file-only Agg backend (a clear error when the extra is missing)."""
    from trackproc.pipeline.plotting import require_matplotlib

    require_matplotlib()
    import matplotlib

    matplotlib.use("Agg", force=True)
    import matplotlib.pyplot as plt

    return plt


def encode(fig, fmt: str = "png") -> bytes:
    plt = pyplot()
    buffer = io.BytesIO()
    fig.savefig(buffer, format=fmt, dpi=90)
    plt.close(fig)
    return buffer.getvalue()


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
        ax.legend(fontsize=7, loc="upper right", markerscale=3)
    axes[-1, 0].set_xlabel(f"hours since {t0.isoformat()}")
    fig.suptitle("residuals, observed - computed (RMS per pass in the legend)", fontsize=10)
    fig.tight_layout()
    return encode(fig)

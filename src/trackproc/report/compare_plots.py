"""The figure of ``trackproc compare``: residuals per pass and kind, raw and after the fitted trend."""

from __future__ import annotations

import io

import numpy as np
import pandas as pd

from trackproc.report.plots import pyplot


def plot_bytes(residuals: pd.DataFrame, summary: dict, max_panels: int = 24) -> bytes:
    """PNG: one panel per pass and kind (at most ``max_panels``), residual (observed −
    predicted) in grey on the right axis, after removing the fitted offset/drift in colour on the
    left axis, in the kind's unit
    (angles in degrees), with the RMS after removal in the title."""
    plt = pyplot()

    entries = summary["passes"][:max_panels]
    n = len(entries)
    cols = 1 if n <= 4 else 2
    rows = (n + cols - 1) // cols
    fig, axes = plt.subplots(rows, cols, figsize=(6 * cols, 2.4 * rows), squeeze=False)
    for ax, entry in zip(axes.ravel(), entries):
        sub = residuals[(residuals["pass_id"] == entry["pass_id"]) & (residuals["kind"] == entry["kind"])]
        scale, unit = (180.0 / np.pi, "deg") if entry["unit"] == "rad" else (1.0, entry["unit"])
        t = (sub["time"] - sub["time"].min()).dt.total_seconds().to_numpy()
        raw_ax = ax.twinx()       # the raw residual is offset by the trend: its own axis, in grey
        raw_ax.plot(t, sub["residual"].to_numpy() * scale, ".", ms=1, color="0.75")
        raw_ax.set_ylabel(f"observed - predicted, {unit}", fontsize=7, color="0.5")
        raw_ax.tick_params(labelsize=6, colors="0.5")
        ax.set_zorder(raw_ax.get_zorder() + 1)
        ax.patch.set_visible(False)
        ax.plot(t, sub["residual_after"].to_numpy() * scale, ".", ms=2, color="C0",
                label=f"after removing {summary['remove']}")
        ax.axhline(0.0, color="0.3", lw=0.6)
        ax.set_title(f"{entry['pass_id']} {entry['kind']}: RMS {entry['rms'] * scale:.3g} {unit} "
                     f"(raw {entry['rms_raw'] * scale:.3g})", fontsize=8)
        ax.set_ylabel(unit, fontsize=8)
        ax.set_xlabel(f"s since {entry['start']}", fontsize=7)
        ax.legend(fontsize=6, loc="upper right", markerscale=3)
    for ax in axes.ravel()[n:]:
        ax.set_visible(False)
    fig.tight_layout()
    buf = io.BytesIO()
    fig.savefig(buf, format="png", dpi=90)
    plt.close(fig)
    return buf.getvalue()

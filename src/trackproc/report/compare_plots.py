"""The figure of ``trackproc compare``: residuals per pass and kind, raw and after the fitted trend."""

from __future__ import annotations

import numpy as np
import pandas as pd

from trackproc.report.plots import encode, legend_outside, pyplot


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
    # 8 x 4.5 in for one panel, 3 in a row more for each further row, at 100 dpi
    fig, axes = plt.subplots(rows, cols, figsize=(8 * cols, max(4.5, 3.0 * rows)), squeeze=False,
                             layout="constrained")
    for ax, entry in zip(axes.ravel(), entries):
        sub = residuals[(residuals["pass_id"] == entry["pass_id"]) & (residuals["kind"] == entry["kind"])]
        scale, unit = (180.0 / np.pi, "deg") if entry["unit"] == "rad" else (1.0, entry["unit"])
        t = (sub["time"] - sub["time"].min()).dt.total_seconds().to_numpy()
        raw_ax = ax.twinx()       # the raw residual is offset by the trend: its own axis, in grey
        raw, = raw_ax.plot(t, sub["residual"].to_numpy() * scale, ".", ms=1, color="0.75",
                           label="observed - predicted (raw, right axis)")
        raw_ax.set_ylabel(f"raw [{unit}]", fontsize=7, color="0.5")
        raw_ax.tick_params(labelsize=6, colors="0.5")
        ax.set_zorder(raw_ax.get_zorder() + 1)
        ax.patch.set_visible(False)
        after, = ax.plot(t, sub["residual_after"].to_numpy() * scale, ".", ms=2, color="C0",
                         label=f"after removing {summary['remove']} (left axis)")
        ax.axhline(0.0, color="0.3", lw=0.6)
        ax.set_title(f"{entry['pass_id']} {entry['kind']}: RMS {entry['rms'] * scale:.3g} {unit} "
                     f"(raw {entry['rms_raw'] * scale:.3g})", fontsize=8)
        ax.set_ylabel(f"after removal [{unit}]", fontsize=8)
        ax.set_xlabel(f"s since {entry['start']}", fontsize=7)
    for ax in axes.ravel()[n:]:
        ax.set_visible(False)
    if n:  # the same two series in every panel: one legend, above them
        fig.legend([after, raw], [after.get_label(), raw.get_label()], loc="outside upper center", ncol=2,
                   fontsize=8, markerscale=4, frameon=False)
    return encode(fig)

"""The figure of ``trackproc requirements``: seed 003 Fig. 3, sample spacing against the angle sigma."""

from __future__ import annotations

import numpy as np

from trackproc.pipeline.requirements import FIG3_G, RequirementsResult
from trackproc.report.plots import encode, legend_outside, pyplot


def plot_bytes(result: RequirementsResult | None = None, sigma_max_rad: float = 0.01) -> bytes:
    """PNG of Fig. 3: Δt = (g/σ)² against σ for the paper's g values, and the grid's g range;
    σ shown in degrees (g is in radians, as in the paper)."""
    plt = pyplot()

    sigma = np.linspace(sigma_max_rad / 200, sigma_max_rad, 400)
    deg = np.degrees(sigma)
    fig, ax = plt.subplots(figsize=(8, 5.5))
    for k, g in enumerate(FIG3_G, 1):
        ax.plot(deg, (g / sigma) ** 2, color=f"C{k - 1}", label=f"{k}: g = {g * 1e3:g}e-3")
    if result is not None:
        gs = sorted(c.g for c in result.cells if c.g > 0)
        picks = gs if len(gs) <= 6 else [gs[0], gs[len(gs) // 2], gs[-1]]
        for k, g in enumerate(picks):
            ax.plot(deg, (g / sigma) ** 2, "--", color="0.2", lw=0.9, dashes=(2 + 2 * k, 2),
                    label=f"this grid: g = {g * 1e3:.2f}e-3")
    ax.set_ylim(0, 20)
    ax.set_xlim(0, float(np.degrees(sigma_max_rad)))
    ax.set_xlabel(f"angle sigma [deg] ({np.degrees(sigma_max_rad):.3g} deg = {sigma_max_rad:g} rad)")
    ax.set_ylabel("sample spacing dt [s]")
    ax.set_title("dt = (g / sigma)^2, sigma in rad (seed 003 Fig. 3)\ndashed: this grid's g (min, median, max)",
                 fontsize=10)
    ax.grid(alpha=0.3)
    legend_outside(ax, fontsize=8)
    fig.tight_layout()
    return encode(fig, dpi=110)

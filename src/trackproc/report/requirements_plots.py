"""The figure of ``trackproc requirements``: seed 003 Fig. 3, sample spacing against the angle sigma."""

from __future__ import annotations

import io

import numpy as np

from trackproc.pipeline.requirements import FIG3_G, RequirementsResult
from trackproc.report.plots import pyplot


def plot_bytes(result: RequirementsResult | None = None, sigma_max_rad: float = 0.01) -> bytes:
    """PNG of Fig. 3: Δt = (g/σ)² against σ for the paper's g values, and the grid's g range."""
    plt = pyplot()

    sigma = np.linspace(sigma_max_rad / 200, sigma_max_rad, 400)
    fig, ax = plt.subplots(figsize=(8, 5.5))
    for k, g in enumerate(FIG3_G, 1):
        ax.plot(sigma, (g / sigma) ** 2, color=f"C{k - 1}", label=f"{k}: g = {g * 1e3:g}e-3")
    if result is not None:
        gs = sorted(c.g for c in result.cells if c.g > 0)
        picks = gs if len(gs) <= 6 else [gs[0], gs[len(gs) // 2], gs[-1]]
        for k, g in enumerate(picks):
            ax.plot(sigma, (g / sigma) ** 2, "--", color="0.2", lw=0.9, dashes=(2 + 2 * k, 2),
                    label=f"this grid: g = {g * 1e3:.2f}e-3")
    ax.set_ylim(0, 20)
    ax.set_xlim(0, sigma_max_rad)
    ax.set_xlabel("sigma, rad (0.01 rad = 34.4')")
    ax.set_ylabel("sample spacing dt, s")
    ax.set_title("dt = (g / sigma)^2 (seed 003 Fig. 3); dashed: this grid's g (min, median, max)", fontsize=10)
    ax.grid(alpha=0.3)
    ax.legend(fontsize=8)
    buf = io.BytesIO()
    fig.savefig(buf, format="png", dpi=110, bbox_inches="tight")
    plt.close(fig)
    return buf.getvalue()

"""Report figures (issue 16): residuals per kind in their own units (degrees for angles) with the
RMS of each pass, checked against numpy on a frame whose residuals are known."""

import numpy as np
import pandas as pd
import pytest

pytest.importorskip("matplotlib")

from trackproc.report.plots import residuals_png, rms_by_pass  # noqa: E402


def _frame():
    rng = np.random.default_rng(1)
    t = pd.date_range("2026-03-20T09:30:00Z", periods=200, freq="10s")
    rows = []
    for kind, sigma in (("range", 5.0), ("elevation", np.radians(0.01))):
        for i, time in enumerate(t):
            rows.append({"time": time, "station": "ZHY" if i < 100 else "KIR",
                         "pass_id": "ZHY-001" if i < 100 else "KIR-001", "kind": kind,
                         "residual": rng.normal(0, sigma), "edited": i == 7})
    return pd.DataFrame(rows)


def test_rms_per_pass_in_display_units():
    frame = _frame()
    rms = rms_by_pass(frame)
    el = frame[(frame["kind"] == "elevation") & (frame["pass_id"] == "ZHY-001") & ~frame["edited"]]
    assert rms[("elevation", "ZHY-001")][0] == pytest.approx(np.degrees(np.sqrt(np.mean(el["residual"] ** 2))))
    assert rms[("elevation", "ZHY-001")][1] == 99          # the edited sample left out
    assert 0.007 < rms[("elevation", "KIR-001")][0] < 0.013   # degrees, not radians
    assert 4.0 < rms[("range", "KIR-001")][0] < 6.0


def test_png_is_written():
    png = residuals_png(_frame())
    assert png[:8] == b"\x89PNG\r\n\x1a\n" and len(png) > 10_000


def test_refine_figure_from_a_refinement(tmp_path):
    """``refine --plot`` on the shipped pass: the figure is written beside the state file."""
    from pathlib import Path

    from trackproc.cli.app import main

    sample = Path(__file__).resolve().parents[2] / "sample_data"
    passfile = tmp_path / "p.parquet"
    assert main(["-q", "ingest", str(sample / "doppler_pass.csv"), "--stations", str(sample / "stations.csv"),
                 "--carrier-hz", "2.2e9", "--mode", "one-way", "-o", str(passfile)]) == 0
    assert main(["-q", "refine", str(passfile), "--initial", str(sample / "stale.json"), "--doppler-bias",
                 "offset+drift", "--plot", str(tmp_path / "r.png"), "-o", str(tmp_path / "r.json")]) == 0
    assert (tmp_path / "r.png").read_bytes()[:4] == b"\x89PNG" and (tmp_path / "r.json").exists()


def test_detect_figure(tmp_path):
    from pathlib import Path

    from trackproc.cli.app import main

    sample = Path(__file__).resolve().parents[2] / "sample_data"
    passfile = tmp_path / "b.parquet"
    assert main(["-q", "simulate", "--ballistic", str(sample / "nominal.json"), "--stations",
                 str(sample / "stations.csv"), "--hypothesis", "h1", "--step", "2", "--elevation-mask-deg", "0",
                 "--seed", "1", "-o", str(passfile)]) == 0
    assert main(["-q", "detect", str(passfile), "--nominal", str(sample / "nominal.json"), "--plot",
                 str(tmp_path / "d.png"), "-o", str(tmp_path / "d.json")]) == 0
    assert (tmp_path / "d.png").read_bytes()[:4] == b"\x89PNG"


def test_smooth_figures_one_per_pass_png_and_pdf(tmp_path):
    from pathlib import Path

    from trackproc.cli.app import main

    sample = Path(__file__).resolve().parents[2] / "sample_data"
    assert main(["-q", "smooth", str(sample / "multistation.parquet"), "--kinds", "elevation", "--plot",
                 str(tmp_path / "s.png"), "-o", str(tmp_path / "s.parquet")]) == 0
    pngs = sorted(p.name for p in tmp_path.glob("s-*.png"))
    assert len(pngs) == 14 and all(p.endswith("-elevation.png") for p in pngs)   # 14 passes, one figure each
    assert main(["-q", "smooth", str(sample / "multistation.parquet"), "--kinds", "elevation", "--plot",
                 str(tmp_path / "s.pdf"), "-o", str(tmp_path / "s2.parquet")]) == 0
    pdf = (tmp_path / "s.pdf").read_bytes()
    assert pdf[:4] == b"%PDF" and pdf.count(b"/Type /Page\n") + pdf.count(b"/Type /Page ") + pdf.count(b"/Type/Page") >= 1

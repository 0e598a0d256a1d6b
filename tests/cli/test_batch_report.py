"""``trackproc batch`` writes ``report.html``: a self-contained page of the run (one table row per
input and window, sortable, links to the outputs, figures inline), checked by parsing it and,
where Chromium is installed, by rendering it headless."""

from __future__ import annotations

import json
import shutil
import subprocess
from html.parser import HTMLParser
from pathlib import Path
from urllib.parse import unquote

import pytest

from test_batch import refine_config, refine_passes  # noqa: F401  (the fixture)


class Page(HTMLParser):
    """Rows of the results table (cells' text), links, image sources, script and style bodies,
    and every attribute value (to look for network references)."""

    def __init__(self):
        super().__init__()
        self.rows, self.links, self.images, self.attrs, self.scripts, self.svgs = [], [], [], [], [], []
        self._in_results = self._in_body = False
        self._row = self._cell = None
        self._script = None

    def handle_starttag(self, tag, attrs):
        attrs = dict(attrs)
        self.attrs.extend(v for v in attrs.values() if v)
        if tag == "table" and attrs.get("id") == "results":
            self._in_results = True
        elif tag == "tbody" and self._in_results:
            self._in_body = True
        elif tag == "tr" and self._in_body:
            self._row = []
        elif tag == "td" and self._row is not None:
            self._cell = []
        elif tag == "a":
            self.links.append(attrs.get("href"))
        elif tag == "img":
            self.images.append(attrs.get("src"))
        elif tag == "svg":
            self.svgs.append(attrs.get("aria-label"))
        elif tag in ("script", "link") and (attrs.get("src") or attrs.get("href")):
            self.scripts.append(attrs.get("src") or attrs.get("href"))

    def handle_endtag(self, tag):
        if tag == "td" and self._cell is not None:
            self._row.append("".join(self._cell).strip())
            self._cell = None
        elif tag == "tr" and self._row is not None:
            self.rows.append(self._row)
            self._row = None
        elif tag == "table":
            self._in_results = self._in_body = False

    def handle_data(self, data):
        if self._cell is not None:
            self._cell.append(data)


def parse(path: Path) -> Page:
    page = Page()
    page.feed(path.read_text(encoding="utf-8"))
    page.close()
    return page


@pytest.fixture(scope="module")
def night(refine_passes, tmp_path_factory):  # noqa: F811
    """ingest -> smooth -> refine -> estimate over the refine passes (one fails: too short)."""
    from typer.testing import CliRunner  # noqa: F401  (run_cli is function-scoped: call main directly)

    from trackproc.cli import app as cli_app

    tmp = tmp_path_factory.mktemp("report")
    out = tmp / "out"
    config = refine_config(tmp / "r.toml", refine_passes, out,
                           batch={"steps": ["ingest", "smooth", "refine", "estimate"]},
                           estimate={"initial": str(refine_passes / "stale.json"), "dut1": 0.0,
                                     "doppler_bias": "offset"})
    return config, out


def test_report_lists_every_input_links_its_outputs_and_fetches_nothing(night, run_cli):
    config, out = night
    run = run_cli(["batch", config, "--workers", "1"])
    assert run.exit_code == 3, run.stderr
    summary = json.loads((out / "summary.json").read_text())
    page = parse(out / "report.html")
    records = summary["inputs"] + summary["estimates"]
    # one row per input and window, in the summary's order, with its status and quality verdict
    assert [r[1].split(" (")[0] for r in page.rows] == [r["name"] for r in records]
    for row, record in zip(page.rows, records):
        assert row[0] == record["task"] and row[2] == record["status"]
        assert row[3] == (record["numbers"].get("quality") or "" if record["status"] == "ok" else "")
        assert row[5] == (record["numbers"].get("decision") or "")
    failed = [row for row in page.rows if row[2] == "failed"]
    assert len(failed) == 1 and "too few samples" in failed[0][-1]
    assert any(r["numbers"].get("decision") for r in records)  # the decision column is filled
    # every link resolves to a file of the output directory; every output is linked
    local = [unquote(h) for h in page.links]
    assert all((out / h).is_file() for h in local), [h for h in local if not (out / h).is_file()]
    assert {o for r in records for o in r["outputs"]} <= set(local)
    assert {"summary.json", "summary.csv"} <= set(local)
    # self-contained: no external script or style, no URL with a scheme other than data:
    text = (out / "report.html").read_text()
    assert page.scripts == [] and "http://" not in text and "https://" not in text and "//" not in \
        "".join(a for a in page.attrs if not a.startswith("data:"))
    # the figures are inline: the overview an SVG (its content: tests/report/test_batch_svg.py), the
    # window's residuals a PNG
    assert len(page.svgs) == 1 and "per input" in page.svgs[0]
    assert len(page.images) == 1 and all(s.startswith("data:image/png;base64,") for s in page.images)
    assert "<script>" in text and "sortable" in text
    # the report is rewritten with the run: a rerun (all up to date) marks the rows so
    assert run_cli(["batch", config, "--workers", "1"]).exit_code == 3
    rerun = parse(out / "report.html")
    assert len(rerun.rows) == len(records) and all("(up to date)" in r[1] for r in rerun.rows if r[2] == "ok")


def test_report_without_matplotlib_is_a_plain_table(tmp_path):
    from trackproc.report.batch_html import report_html

    summary = {"started_utc": "2026-01-01T00:00:00Z", "counts": {"inputs": 1}, "exit_code": 0,
               "inputs": [{"task": "pass", "name": "a<b>&\"c", "status": "ok", "skipped": False,
                           "numbers": {"samples": 10, "rms": 0.5, "rms_unit": "Hz", "kind": "doppler"},
                           "outputs": ["passes/a b.parquet"], "warnings": []}],
               "estimates": []}
    text = report_html(summary, tmp_path, plots=False)
    page = Page()
    page.feed(text)
    assert page.rows[0][1] == 'a<b>&"c' and page.images == []
    assert page.links[-1] == "passes/a%20b.parquet"
    assert "matplotlib is not installed" in text


@pytest.mark.slow
def test_report_renders_in_a_headless_browser(night, run_cli, tmp_path):
    chromium = shutil.which("chromium") or ("/usr/bin/chromium" if Path("/usr/bin/chromium").exists() else None)
    if chromium is None:
        pytest.skip("no chromium installed")
    config, out = night
    if not (out / "report.html").exists():
        assert run_cli(["batch", config, "--workers", "1"]).exit_code == 3
    png = tmp_path / "report.png"
    subprocess.run([chromium, "--headless", "--disable-gpu", "--no-sandbox", f"--screenshot={png}",
                    "--window-size=1400,1000", (out / "report.html").as_uri()],
                   capture_output=True, timeout=120, check=False)
    assert png.is_file() and png.stat().st_size > 10_000

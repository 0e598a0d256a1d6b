"""``OUTPUT/report.html`` of ``trackproc batch``: the night's results on one self-contained page.

One row per input and per estimate window (status, quality verdict and its reasons, the decision
on the initial orbit, key numbers, links to the outputs), in a table that sorts when a header is
clicked; the fit and residual RMS and the RTN sigmas of every input as an inline SVG (written as
text, report/svg.py), and, with matplotlib installed, the residuals of every estimate window as
inline PNG images (``data:`` URIs). Nothing is fetched:
the CSS and the few lines of JavaScript are inline, links are relative to the output directory,
so the page works from a copied directory, a mail attachment's folder or ``file://``.
"""

from __future__ import annotations

import base64
import html
import logging
import math
from pathlib import Path
from typing import Optional
from urllib.parse import quote

from trackproc.io.atomic import write_text

log = logging.getLogger("trackproc.batch")

REPORT_HTML = "report.html"
#: Estimate windows whose residuals are drawn (the latest ones); each image is ~100 kB.
MAX_WINDOW_PLOTS = 8

_CSS = """
body{font-family:system-ui,-apple-system,"Segoe UI",Roboto,sans-serif;margin:1.5em;color:#222}
h1{font-size:1.4em}h2{font-size:1.15em;margin-top:1.6em}
table{border-collapse:collapse;font-size:0.85em}
th,td{border:1px solid #ccc;padding:3px 6px;text-align:left;vertical-align:top}
th{background:#eee;cursor:pointer;user-select:none;position:sticky;top:0}
th.asc::after{content:" \\25B2"}th.desc::after{content:" \\25BC"}
td.num{text-align:right;font-variant-numeric:tabular-nums}
tr.failed td.status,tr.rejected td.quality{background:#f8d0d0}
tr.suspect td.quality{background:#fbeeb8}tr.ok td.status{background:#d6f0d6}
.muted{color:#777}img,svg.figure{max-width:100%;height:auto;border:1px solid #ddd;margin:0.4em 0}
dl{display:grid;grid-template-columns:max-content auto;gap:2px 12px}dt{font-weight:bold}dd{margin:0}
"""

# Click a header: sort its table's rows by that column (numbers by data-v, text otherwise),
# click again to reverse.
_JS = """
document.querySelectorAll("table.sortable th").forEach(function(th, col){
  th.addEventListener("click", function(){
    var body = th.closest("table").tBodies[0], rows = Array.from(body.rows);
    var asc = !th.classList.contains("asc");
    th.parentNode.querySelectorAll("th").forEach(function(h){h.classList.remove("asc","desc");});
    th.classList.add(asc ? "asc" : "desc");
    function key(r){var c = r.cells[col], v = c.getAttribute("data-v");
      return v !== null && v !== "" && !isNaN(v) ? parseFloat(v) : c.textContent.toLowerCase();}
    rows.sort(function(a, b){var x = key(a), y = key(b);
      if (typeof x !== typeof y) {x = String(x); y = String(y);}
      return (x < y ? -1 : x > y ? 1 : 0) * (asc ? 1 : -1);});
    rows.forEach(function(r){body.appendChild(r);});
  });
});
"""

#: Table columns: (header, how a record gives the cell); numbers carry their unit in the header.
_COLUMNS = ("task", "input", "status", "quality", "reasons", "decision", "samples", "passes", "fit RMS",
            "refined / estimated", "residual RMS", "σ radial [m]", "σ along [m]", "σ cross [m]", "seconds",
            "outputs", "error / warnings")


def _e(text) -> str:
    return html.escape("" if text is None else str(text), quote=True)


def _num(value, digits: int = 4) -> str:
    """A number with ``digits`` significant digits ('' when missing or not finite)."""
    if value is None or isinstance(value, bool):
        return ""
    try:
        value = float(value)
    except (TypeError, ValueError):
        return ""
    if not math.isfinite(value):
        return ""
    if 10 ** digits <= abs(value) < 1e12:  # 12345.6 as 12346, not 1.235e+04
        return f"{value:.0f}"
    return f"{value:.{digits}g}"


def _cell(text: str = "", value=None, cls: str = "") -> str:
    attrs = f' class="{cls}"' if cls else ""
    if value is not None and _num(value):
        attrs += f' data-v="{float(value)!r}"'
    return f"<td{attrs}>{text}</td>"


def _link(rel: str) -> str:
    return f'<a href="{_e(quote(rel))}">{_e(rel)}</a>'


def _row(record: dict) -> str:
    n = record.get("numbers") or {}
    status = record.get("status") or ""
    quality = n.get("quality") if status == "ok" else None
    classes = " ".join(dict.fromkeys(c for c in (status, quality or "") if c))
    fit = (f"{_e(n.get('kind'))} {_num(n.get('rms'))} {_e(n.get('rms_unit'))}" if n.get("rms") is not None else "")
    if record.get("task") in ("estimate", "filter"):
        solved = (f"window of {len(record.get('members') or [])} input(s)" if record.get("task") == "estimate"
                  else f"filter over {len(record.get('members') or [])} input(s), state carried")
        if n.get("epoch_utc"):
            solved += f", epoch {_e(n['epoch_utc'])}"
        residual = f"WRMS {_num(n.get('wrms'))}" if n.get("wrms") is not None else ""
        residual_value = n.get("wrms")
    else:
        solved = _e(n.get("refined_pass") or "")
        if n.get("traverse_utc"):
            solved += f" at {_e(n['traverse_utc'])}"
        residual = (f"{_num(n.get('residual_rms'))} {_e(n.get('residual_rms_unit'))}"
                    if n.get("residual_rms") is not None else "")
        residual_value = n.get("residual_rms")
    notes = []
    if record.get("error"):
        notes.append(f"<b>{_e(record['error'])}</b>")
    notes.extend(_e(w) for w in record.get("warnings") or [])
    outputs = "<br>".join(_link(rel) for rel in record.get("outputs") or [])
    name = _e(record.get("name"))
    if record.get("skipped"):
        name += ' <span class="muted">(up to date)</span>'
    cells = [
        _cell(_e(record.get("task"))), _cell(name), _cell(_e(status), cls="status"),
        _cell(_e(quality or ""), cls="quality"), _cell(_e((n.get("quality_reasons") or "").replace(",", ", "))),
        _cell(_e(n.get("decision") or "")), _cell(_e(n.get("samples", "")), n.get("samples"), "num"),
        _cell(_e(n.get("passes", "")), n.get("passes"), "num"), _cell(fit, n.get("rms"), "num"), _cell(solved),
        _cell(residual, residual_value, "num"),
        *(_cell(_num(n.get(k), 3), n.get(k), "num") for k in ("sigma_radial_m", "sigma_along_m", "sigma_cross_m")),
        _cell(_num(record.get("seconds"), 3), record.get("seconds"), "num"), _cell(outputs),
        _cell("<br>".join(notes)),
    ]
    return f'<tr class="{_e(classes)}">' + "".join(cells) + "</tr>"


def _png_img(data: bytes, alt: str) -> str:
    return f'<img alt="{_e(alt)}" src="data:image/png;base64,{base64.b64encode(data).decode("ascii")}">'


def _have_matplotlib() -> bool:
    """Whether matplotlib is installed, without importing it (~0.1 s): only the window figures need it."""
    import importlib.util
    import sys

    if "matplotlib" in sys.modules:  # imported already, or blocked (None)
        return sys.modules["matplotlib"] is not None
    return importlib.util.find_spec("matplotlib") is not None


def overview_svg(records: list) -> Optional[str]:
    """Per input (in the table's order): the smoothing fit RMS of its primary kind, the refined
    pass's residual RMS, and the refined state's RTN 1-sigma (a log scale where a panel's values
    span more than a decade; one marker per quantity), as an inline ``<svg>``; None when no input
    has any of them. Written as text (report/svg.py): no matplotlib, a few milliseconds."""
    from trackproc.report.svg import Panel, Series, scatter_panels

    ok = [r for r in records if r.get("task") == "pass" and r.get("status") == "ok"]
    if not ok:
        return None
    numbers = [r.get("numbers") or {} for r in ok]

    def values(key):
        out = []
        for n in numbers:
            try:
                out.append(float(n.get(key)) if n.get(key) is not None else None)
            except (TypeError, ValueError):
                out.append(None)
        return out

    panels = []
    fit = Series(", ".join(sorted({str(n.get("kind")) for n in numbers if n.get("rms") is not None})),
                 values("rms"))
    residual = Series("residual RMS", values("residual_rms"))
    sigmas = [Series(label, values(key)) for label, key in (
        ("radial", "sigma_radial_m"), ("along-track", "sigma_along_m"), ("cross-track", "sigma_cross_m"))]
    units = sorted({str(n.get("rms_unit")) for n in numbers if n.get("rms") is not None})
    candidates = [Panel(f"smoothing fit RMS [{', '.join(units)}]", [fit]),
                  Panel("refine residual RMS [" + str(next((n.get("residual_rms_unit") for n in numbers
                                                            if n.get("residual_rms") is not None), "")) + "]",
                        [residual]),
                  Panel("refined state 1-sigma [m]", sigmas)]
    panels = [p for p in candidates if p.finite()]
    if not panels:
        return None
    return scatter_panels(panels, [str(r.get("name")) for r in ok],
                          "per input: fit and residual RMS, refined state sigma",
                          xlabel=f"input (index of the {len(ok)} processed inputs, in the table's order)")


def window_png(out: Path, record: dict) -> Optional[bytes]:
    """The residuals of an estimate window (its ``.residuals.parquet``), or None without one."""
    rel = next((o for o in record.get("outputs") or [] if o.endswith(".residuals.parquet")), None)
    if rel is None or not (out / rel).is_file():
        return None
    import pyarrow.parquet as pq  # only when a figure is drawn

    from trackproc.report.plots import residuals_png

    frame = pq.read_table(out / rel).to_pandas()
    if not len(frame):
        return None
    return residuals_png(frame)


def report_html(summary: dict, out: Path, plots: Optional[bool] = None) -> str:
    """The page for ``summary`` (the summary.json document) of the output directory ``out``;
    ``plots``: draw the figures (default: when matplotlib is installed)."""
    plots = _have_matplotlib() if plots is None else plots
    inputs, windows = summary.get("inputs") or [], summary.get("estimates") or []
    counts = summary.get("counts") or {}
    title = f"trackproc batch, {summary.get('started_utc', '')}"
    parts = ["<!DOCTYPE html>", '<html lang="en"><head><meta charset="utf-8">',
             '<meta name="viewport" content="width=device-width, initial-scale=1">',
             f"<title>{_e(title)}</title><style>{_CSS}</style></head><body>", f"<h1>{_e(title)}</h1>"]
    facts = [("exit status", summary.get("exit_code")), ("steps", " → ".join(summary.get("steps") or [])),
             ("inputs", f"{counts.get('inputs_ok', 0)} ok, {counts.get('inputs_failed', 0)} failed, "
                        f"{counts.get('inputs_skipped', 0)} up to date, of {counts.get('inputs', 0)}"),
             ("quality", f"{counts.get('quality_suspect', 0)} suspect, {counts.get('quality_rejected', 0)} rejected")]
    if windows:
        facts.append(("estimate windows", f"{counts.get('windows_ok', 0)} ok, {counts.get('windows_failed', 0)} "
                                          f"failed, of {counts.get('windows', 0)}"))
    facts += [("finished", summary.get("finished_utc")), ("time", f"{_num(summary.get('seconds'), 3)} s"),
              ("executor", summary.get("executor")), ("trackproc", summary.get("trackproc_version"))]
    parts.append("<dl>" + "".join(f"<dt>{_e(k)}</dt><dd>{_e(v)}</dd>" for k, v in facts)
                 + f"<dt>summaries</dt><dd>{_link('summary.json')} {_link('summary.csv')}</dd></dl>")
    parts.append("<h2>Results</h2><p class=\"muted\">Click a column header to sort.</p>")
    parts.append('<table class="sortable" id="results"><thead><tr>'
                 + "".join(f"<th>{_e(c)}</th>" for c in _COLUMNS) + "</tr></thead><tbody>")
    parts.extend(_row(r) for r in inputs + windows)
    parts.append("</tbody></table>")
    try:
        overview = overview_svg(inputs)
        if overview:
            parts.append("<h2>Per input</h2>" + overview)
    except Exception as exc:  # as the PNG figures below: the table stays
        log.warning("report.html: overview figure left out (%s: %s)", type(exc).__name__, exc)
        parts.append(f'<p class="muted">Overview figure left out: {_e(type(exc).__name__)}: {_e(exc)}</p>')
    if plots:
        figures = []
        try:
            for record in [w for w in windows if w.get("status") == "ok"
                           and w.get("task", "estimate") == "estimate"][-MAX_WINDOW_PLOTS:]:
                image = window_png(out, record)
                if image:
                    figures.append(f"<h2>Estimate window {_e(record.get('name'))}: residuals</h2>"
                                   + _png_img(image, f"residuals of window {record.get('name')}"))
        except Exception as exc:  # a figure must not cost the night its report: the table stays
            log.warning("report.html: figures left out (%s: %s)", type(exc).__name__, exc)
            figures = [f'<p class="muted">Figures left out: {_e(type(exc).__name__)}: {_e(exc)}</p>']
        parts.extend(figures)
    else:
        parts.append('<p class="muted">No residual figures of the estimate windows: matplotlib is not installed '
                     "(pip install 'trackproc[plot]').</p>")
    parts.append(f"<script>{_JS}</script></body></html>\n")
    return "\n".join(parts)


def write_report(out: Path, summary: dict) -> Path:
    """Write ``out/report.html`` atomically; returns its path."""
    path = Path(out) / REPORT_HTML
    write_text(path, report_html(summary, Path(out)))
    return path

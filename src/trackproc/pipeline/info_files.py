"""What a file is, and a short summary of it, for ``trackproc info``: every kind of file trackproc
reads or writes.

:func:`describe` sniffs the content (first bytes, header line, JSON keys; the file name only
where the content cannot tell, e.g. a DopTrack YAML sidecar), calls the project's own reader of
that kind (:mod:`trackproc.io`) and returns ``(summary, text)``: a JSON-ready mapping and the
text a person reads. A file of no known kind is an input error that lists :data:`KINDS`.

Over 400 lines because it knows every kind of file (one short describer each, beside the sniffing
that picks it); split by kind, the sniffing would import them all anyway.
"""

from __future__ import annotations

import gzip
import json
import math
import os
import tempfile
from contextlib import contextmanager
from io import BytesIO
from pathlib import Path

import numpy as np

from trackproc.constants import WGS84_A
from trackproc.errors import InputError
from trackproc.io.atomic import is_stdio
from trackproc.io import cpf, crd, doptrack, orekit_aer, orekit_config, sinex
from trackproc.io.columns import column_numbers, column_strings, column_times, sniff_container, source_table
from trackproc.io.cpf import parse_cpf
from trackproc.io.doptrack import load_sidecar
from trackproc.io.ephemeris import parse_ephemeris
from trackproc.io.passfile import COLUMNS, parse_pass_table
from trackproc.io.problems import Problems
from trackproc.io.raw import KIND_UNITS
from trackproc.io.statefile import format_epoch
from trackproc.io.stations import parse_stations
from trackproc.io.tabular import read_raw
from trackproc.io.tle import parse_tle, tle_epoch
from trackproc.isotime import iso_utc
from trackproc.pipeline import info as base

#: The kinds :func:`describe` recognises (named in the error for anything else).
KINDS = ("canonical pass file", "raw pass table (CSV, Parquet, Arrow)", "stations table", "ephemeris",
         "state JSON", "TLE / TLE catalogue", "CCSDS OPM", "CCSDS OEM", "CCSDS TDM", "ILRS CRD", "ILRS CPF",
         "SINEX", "ICGEM gravity field (.gfc, .gfc.gz)", "DopTrack CSV", "DopTrack YAML", "Orekit .aer", "Orekit OD configuration (.in)",
         "detect nominal JSON", "smooth summary", "batch summary (JSON, CSV)", "residuals table",
         "requirements table (CSV, Markdown)", "pass schedule (CSV, JSON)", "trackproc JSON or CSV output")

_GZIP = b"\x1f\x8b"


def not_known(source: str, found: str) -> InputError:
    return InputError("not a file trackproc knows", file=source, found=found,
                      expected="one of the recognised kinds: " + ", ".join(KINDS))


# --------------------------------------------------------------------------- entry point


def describe(data: bytes, path: str) -> tuple[dict, str | None]:
    """``(summary, text)`` of the file whose bytes are ``data`` (``path``: its name, ``-`` for stdin).
    ``text`` is None where the summary's generic rendering (:func:`format_mapping`) is meant."""
    source = "<stdin>" if is_stdio(path) else str(path)
    if not data.strip():
        raise InputError("empty input", file=source, row=1, found="no data",
                         expected="one of the recognised kinds: " + ", ".join(KINDS))
    if data[:2] == _GZIP:
        return _gzipped(data, path, source), None
    if sniff_container(data) != "text":
        return _table(data, path, source)
    head = data[:65536]
    text = head.decode("utf-8", errors="replace").lstrip("\ufeff").lstrip()
    first = text.split("\n", 1)[0].strip()
    if text.startswith("{"):
        return _json(data, source), None
    for kind, summarize in (("OPM", base.opm_info), ("OEM", base.oem_info), ("TDM", base.tdm_info)):
        if text.startswith(f"CCSDS_{kind}_VERS"):
            return summarize(data, source), None
    if sinex.looks_like_sinex(data):
        return sinex_info(data, source), None
    if crd.looks_like_crd(text):
        return raw_info(data, path, source, "ILRS CRD (laser ranging normal points)"), None
    if cpf.looks_like_cpf(text):
        return cpf_info(data, source), None
    if _looks_like_icgem(head):
        return icgem_info(data, path, source), None
    if _looks_like_tle(text):
        return tle_catalogue_info(data, source), None
    if _looks_like_doptrack_yaml(text):
        return doptrack_yaml_info(data, path, source), None
    if doptrack.looks_like_doptrack(text):
        return raw_info(data, path, source, "DopTrack pass (received frequency, one-way Doppler)"), None
    if orekit_aer.looks_like_aer(text) or source.lower().endswith(".aer"):
        return raw_info(data, path, source, "Orekit .aer measurements (azimuth, elevation, range)"), None
    if orekit_config.looks_like_orekit_config(text):
        return orekit_config_info(data, source), None
    if first.startswith("|") or (first and "\n|" in text[:2000] and not first.startswith("#")):
        return markdown_info(data, source), None
    header = next((line for line in text.splitlines() if line.strip() and not line.startswith("#")), "")
    if "," not in header:
        raise not_known(source, f"text starting {header[:40]!r}" if header else "only comment lines")
    return _table(data, path, source)


# --------------------------------------------------------------------------- tables


def _has(columns, *names) -> bool:
    return all(n in columns for n in names)


def _table(data: bytes, path: str, source: str) -> tuple[dict, str | None]:
    """A CSV, Parquet or Arrow table: which one by its columns."""
    table = source_table(data, source)
    columns = set(table.columns)
    if _has(columns, *COLUMNS):
        info = base.summarize(parse_pass_table(data, source), source)
        return base.info_dict(info), base.format_info(info)
    if _has(columns, "time", "x_m", "y_m", "z_m", "vx_m_s", "vy_m_s", "vz_m_s"):
        eph = parse_ephemeris(data, source)
        return base.ephemeris_info(eph.frame, eph.meta, source), None
    if _has(columns, "observed", "computed", "residual"):
        return residuals_info(table, source), None
    if _has(columns, "task", "input", "status"):
        return batch_csv_info(table, source), None
    if _has(columns, "velocity_kms", "angle_deg", "tau_s", "g"):
        return requirements_csv_info(table, source), None
    if _has(columns, "aos_time", "los_time"):
        return schedule_info(table, source), None
    if _has(columns, "station", "lat_deg") and "time" not in columns:
        return stations_info(data, source), None
    if _has(columns, "time", "station") or ("time" in columns and table.meta == {}
                                             and any(c.endswith(("_deg", "_m", "_hz", "_m_s")) for c in columns)):
        return raw_info(data, path, source, "raw pass table (not yet ingested)"), None
    if table.meta:
        return output_table_info(table, source), None
    raise not_known(source, "a table with columns " + ", ".join(c.name for c in table.columns.values()))


def _span(times) -> dict:
    if getattr(getattr(times, "dt", None), "tz", None) is not None:     # a tz-aware pandas column
        times = times.dt.tz_convert("UTC").dt.tz_localize(None)
    times = np.sort(np.asarray(times, dtype="datetime64[ns]"))
    times = times[~np.isnat(times)]
    if not times.size:
        return {"start": None, "end": None, "duration_s": None}
    return {"start": iso_utc(times[0], 3), "end": iso_utc(times[-1], 3),
            "duration_s": float((times[-1] - times[0]) / np.timedelta64(1, "s"))}


def raw_info(data: bytes, path: str, source: str, what: str) -> dict:
    """Samples a reader found in a raw input (before ``trackproc ingest``): per kind (with the
    canonical SI unit), per station, the span, and the reader's own facts (CRD sessions, DopTrack
    satellite and TLE). A row the reader refuses is an input error, as for ingest."""
    raw = read_raw(path, data=data)
    frame, meta = raw.frame, raw.meta
    kinds = {str(k): int(n) for k, n in frame["kind"].value_counts().sort_index().items()}
    out = {"file": source, "kind": what, "samples": int(len(frame)), **_span(frame["time"]),
           "samples_per_kind": kinds, "units": {k: KIND_UNITS.get(k) for k in kinds},
           "samples_per_station": {str(s): int(n) for s, n in frame["station"].value_counts().sort_index().items()}}
    if "pass_id" in frame.columns:
        out["passes"] = int(frame["pass_id"].nunique())
    for key in ("carrier_hz", "doppler_mode"):
        if meta.get(key) is not None:
            out[key] = meta[key]
    stations = meta.get("stations") or {}
    if stations:
        out["stations"] = {str(name): dict(pos) for name, pos in stations.items()}
    dropped = {str(k): int(v) for k, v in (meta.get("dropped") or {}).items() if v}
    if dropped:
        out["invalid_rows"] = dropped
    crd = meta.get("crd")
    if crd:
        out["crd_version"] = crd.get("version")
        out["records"] = crd.get("records")
        out["sessions"] = {s["pass_id"]: {"station": s["station"], "target": s["target"], "start": s["start"],
                                          "end": s["end"], "wavelength_nm": s.get("wavelength_nm")}
                           for s in crd.get("sessions", [])}
        out["meteo_records"] = {st: len(m["time"]) for st, m in (crd.get("meteo") or {}).items()}
    for details in (meta.get("doptrack") or {}).values():
        out.update({"satellite": details.get("satellite"), "norad_id": details.get("norad_id"),
                    "sidecar": details.get("sidecar"), "tca": details.get("tca"), "fca_hz": details.get("fca_hz")})
        out["tle"] = details.get("tle")
    out["next"] = "trackproc ingest FILE -o pass.parquet (validates it into a canonical pass file)"
    return out


def stations_info(data: bytes, source: str) -> dict:
    stations = parse_stations(data, source)
    return {"file": source, "kind": "stations table (WGS-84 geodetic)", "stations": len(stations),
            "positions": {name: {"lat_deg": s.lat_deg, "lon_deg": s.lon_deg, "height_m": s.height_m,
                                 **({"range_bias_m": s.range_bias_m} if s.range_bias_m is not None else {}),
                                 **({"time_sigma_s": s.time_sigma_s} if s.time_sigma_s is not None else {})}
                          for name, s in stations.items()}}


def _numbers(table, name):
    values, missing, wrong = column_numbers(table, table.columns[name])
    return np.where(missing | wrong, np.nan, values)


def _strings(table, name):
    return np.asarray(column_strings(table, table.columns[name]), dtype=object).astype(str)


def _times(table, name="time"):
    problems = Problems(table.rows, table.source)
    times = column_times(table, table.columns[name], problems)
    problems.resolve(drop_invalid=False)
    return times


def residuals_info(table, source: str) -> dict:
    """A residuals table (``estimate``/``refine``/``fit-tle --residuals``, ``compare``): per
    station and kind, the samples, those edited out, the RMS of the residuals (the kind's unit)
    and of the normalized residuals (1 when the sigmas are right)."""
    columns = table.columns
    residual = _numbers(table, "residual")
    station = _strings(table, "station") if "station" in columns else np.full(len(residual), "-", dtype=object)
    kind = _strings(table, "kind") if "kind" in columns else np.full(len(residual), "-", dtype=object)
    unit = _strings(table, "unit") if "unit" in columns else np.full(len(residual), "", dtype=object)
    normalized = _numbers(table, "normalized_residual") if "normalized_residual" in columns else None
    edited = (np.isin(_strings(table, "edited"), ["true", "True", "1"]) if "edited" in columns
              else np.zeros(len(residual), bool))
    per = {}
    for st in sorted(set(station)):
        for k in sorted(set(kind[station == st])):
            sel = (station == st) & (kind == k)
            used = sel & ~edited & np.isfinite(residual)
            entry = {"samples": int(sel.sum()), "edited": int((sel & edited).sum()),
                     "rms": float(np.sqrt(np.mean(residual[used] ** 2))) if used.any() else None,
                     "unit": str(unit[sel][0]) if sel.any() else ""}
            if normalized is not None and used.any():
                entry["normalized_rms"] = float(np.sqrt(np.mean(normalized[used] ** 2)))
            per[f"{st} {k}"] = entry
    out = {"file": source, "kind": "residuals table", "samples": int(len(residual)),
           **(_span(_times(table)) if "time" in columns else {}), "per_station_and_kind": per}
    meta = table.meta
    for key in ("command", "epoch", "force_model"):
        if meta.get(key) is not None:
            out[key] = meta[key]
    return out


def batch_csv_info(table, source: str) -> dict:
    status = _strings(table, "status")
    task = _strings(table, "task")
    out = {"file": source, "kind": "batch summary (CSV, one row per input and window)", "rows": int(len(status)),
           "tasks": {str(t): int((task == t).sum()) for t in sorted(set(task))},
           "status": {str(s): int((status == s).sum()) for s in sorted(set(status))}}
    if "quality" in table.columns:
        quality = _strings(table, "quality")
        counts = {str(q): int((quality == q).sum()) for q in sorted(set(quality)) if q not in ("", "nan", "None")}
        if counts:
            out["quality"] = counts
    failed = [str(n) for n, s in zip(_strings(table, "input"), status) if s not in ("ok", "skipped")]
    if failed:
        out["failed_inputs"] = failed
    return out


def requirements_csv_info(table, source: str) -> dict:
    g = _numbers(table, "g")
    grid = {name: sorted({float(v) for v in _numbers(table, name) if math.isfinite(v)})
            for name in ("velocity_kms", "angle_deg", "tau_s")}
    return {"file": source, "kind": "requirements table (seed 003, g = sigma sqrt(dt))", "rows": int(len(g)),
            "velocity_kms": grid["velocity_kms"], "angle_deg": grid["angle_deg"], "tau_s": grid["tau_s"],
            "g_rad_s05": [float(np.nanmin(g)), float(np.nanmax(g))] if len(g) else None}


def schedule_info(table, source: str) -> dict:
    stations = _strings(table, "station") if "station" in table.columns else np.array([], dtype=object)
    out = {"file": source, "kind": "pass schedule (trackproc passes)", "passes": int(len(table)),
           "passes_per_station": {str(s): int((stations == s).sum()) for s in sorted(set(stations))}}
    if len(table):
        out.update(_span(np.concatenate([_times(table, "aos_time"), _times(table, "los_time")])))
    if "max_elevation_deg" in table.columns and len(table):
        out["max_elevation_deg"] = float(np.nanmax(_numbers(table, "max_elevation_deg")))
    return out


def output_table_info(table, source: str) -> dict:
    meta = table.meta
    out = {"file": source, "kind": "trackproc table", "rows": int(len(table)),
           "columns": [c.name for c in table.columns.values()]}
    for key in ("command", "generator", "epoch", "force_model", "trackproc_version"):
        if meta.get(key) is not None:
            out[key] = meta[key]
    if "time" in table.columns and len(table):
        out.update(_span(_times(table)))
    return out


def markdown_info(data: bytes, source: str) -> dict:
    """A Markdown table written by trackproc (``requirements --format md``, ``passes --format md``):
    its title, columns and rows."""
    text = data.decode("utf-8", errors="replace")
    lines = [line.strip() for line in text.splitlines()]
    rows = [line for line in lines if line.startswith("|")]
    if len(rows) < 2 or not set(rows[1].replace("|", "").strip()) <= set("-: "):
        raise not_known(source, "text that is not a Markdown table")
    header = [c.strip() for c in rows[0].strip("|").split("|")]
    title = next((line for line in lines if line and not line.startswith("|")), "")
    what = ("requirements table (seed 003, Markdown)" if any(h.startswith("V =") for h in header)
            else "pass schedule (Markdown)" if any("AOS" in h.upper() for h in header) else "Markdown table")
    return {"file": source, "kind": what, "title": title, "columns": header, "rows": len(rows) - 2}


# --------------------------------------------------------------------------- JSON


def _json(data: bytes, source: str) -> dict:
    try:
        doc = json.loads(data)
    except (ValueError, RecursionError) as exc:
        raise InputError(f"not valid JSON ({getattr(exc, 'msg', exc.__class__.__name__)})", file=source,
                         row=getattr(exc, "lineno", None), expected="a JSON object trackproc writes or reads") from None
    if not isinstance(doc, dict):
        raise not_known(source, f"a JSON {type(doc).__name__}")
    command = doc.get("command")
    if command == "batch":
        return batch_json_info(doc, source)
    if command == "smooth":
        return smooth_summary_info(doc, source)
    if "impact_time" in doc or ("velocity_kms" in doc and "angle_deg" in doc):
        return nominal_info(data, source)
    meta = doc.get("meta") if isinstance(doc.get("meta"), dict) else {}
    if meta.get("generator") == "trackproc passes":
        return {"file": source, "kind": "pass schedule (JSON)", **{k: meta.get(k) for k in ("orbit", "start", "end")},
                "passes": len(doc.get("passes") or [])}
    if "epoch" in doc or "position_m" in doc:      # the state reader names what is missing
        return base.state_info(data, source)
    if command or "trackproc_version" in doc or meta.get("generator", "").startswith("trackproc"):
        return {"file": source, "kind": f"trackproc {command or meta.get('generator', 'output')} record (JSON)",
                "keys": sorted(doc)}
    raise not_known(source, "a JSON object with keys " + ", ".join(sorted(map(str, doc))[:8]))


def batch_json_info(doc: dict, source: str) -> dict:
    inputs = doc.get("inputs") or []
    status = {}
    for item in inputs:
        status[item.get("status", "?")] = status.get(item.get("status", "?"), 0) + 1
    out = {"file": source, "kind": "batch summary (JSON)", "config_file": doc.get("config_file"),
           "steps": doc.get("steps"), "started": doc.get("started_utc"), "finished": doc.get("finished_utc"),
           "elapsed_s": doc.get("seconds"), "exit_code": doc.get("exit_code"), "counts": doc.get("counts"),
           "inputs_by_status": status}
    failed = [f"{i.get('name')}: {i.get('error')}" for i in inputs if i.get("status") not in ("ok", "skipped")]
    if failed:
        out["failed"] = failed
    return out


def smooth_summary_info(doc: dict, source: str) -> dict:
    fits = doc.get("fits") or []
    rows = {}
    for f in fits:
        entry = {"status": f.get("status"), "samples": f.get("n_samples"), "rejected": f.get("n_rejected"),
                 "degree": f.get("degree")}
        for key in ("rms", "tca_utc", "tca_sigma_s", "fca_hz", "fca_sigma_hz"):
            if f.get(key) is not None:
                entry[key] = f[key]
        if f.get("unit"):
            entry["unit"] = f["unit"]
        rows[f"{f.get('station')} {f.get('pass_id')} {f.get('kind')}"] = entry
    return {"file": source, "kind": "smooth summary (JSON)", "source": doc.get("source"),
            "doppler_mode": doc.get("doppler_mode"), "carrier_hz": doc.get("carrier_hz"),
            "counts": doc.get("counts"), "fits": rows}


def nominal_info(data: bytes, source: str) -> dict:
    from trackproc.pipeline.detect import parse_nominal  # start-up: scipy (the detection test)

    nominal = parse_nominal(data, source)
    return {"file": source, "kind": "detect nominal trajectory (JSON)", **nominal.describe()}


# --------------------------------------------------------------------------- text formats


def _looks_like_tle(text: str) -> bool:
    lines = [line.rstrip() for line in text.splitlines() if line.strip()][:3]
    return any(a.startswith("1 ") and b.startswith("2 ") and len(a) >= 68 for a, b in zip(lines, lines[1:]))


def tle_catalogue_info(data: bytes, source: str) -> dict:
    """One TLE (its elements) or a catalogue (each satellite's name, number and epoch)."""
    from trackproc.pipeline.identify import parse_catalogue  # start-up: SGP4 comparison, propagator

    tles = parse_catalogue(data.decode("ascii", errors="replace"), source)
    if len(tles) == 1:
        return base.tle_info(data, source)
    epochs = [tle_epoch(t) for t in tles]
    return {"file": source, "kind": "TLE catalogue (SGP4 mean elements, TEME)", "tles": len(tles),
            "epochs": [format_epoch(min(epochs)), format_epoch(max(epochs))],
            "satellites": {f"{t.satnum} {t.name or ''}".strip(): format_epoch(e) for t, e in zip(tles, epochs)}}


def cpf_info(data: bytes, source: str) -> dict:
    eph = parse_cpf(data, source)
    r = np.linalg.norm(eph.r_itrf, axis=1)
    steps = np.diff(eph.times) / np.timedelta64(1, "s")
    return {"file": source, "kind": "ILRS CPF prediction (ITRF positions)", "target": eph.target,
            "positions": int(len(r)), **_span(eph.times), "step_s": float(np.median(steps)) if steps.size else None,
            "radius_km": [float(r.min()) / 1e3, float(r.max()) / 1e3] if r.size else None,
            "above_equatorial_radius_km": [float(r.min() - WGS84_A) / 1e3, float(r.max() - WGS84_A) / 1e3]
            if r.size else None,
            "centre_of_mass_corrected": eph.com_corrected}


def orekit_config_info(data: bytes, source: str) -> dict:
    """Orekit's orbit-determination configuration: the initial orbit, the stations and the range
    sigma, through the reader ``import-orekit`` uses (so a file it would refuse is refused here)."""
    cfg = orekit_config.parse_orekit_config(data, source)
    rows = orekit_config.stations(cfg)
    state = orekit_config.initial_state(cfg)
    sigmas = sorted({r["range_sigma_m"] for r in rows if math.isfinite(r["range_sigma_m"])})
    return {"file": source, "kind": "Orekit orbit-determination configuration (.in)",
            "initial_orbit": f"{state['epoch']} {state['frame']}", "stations": len(rows),
            "station_names": ", ".join(r["station"] for r in rows),
            "range_sigma": "/".join(f"{s:g}" for s in sigmas) + " m" if sigmas else None,
            "measurements": cfg.text("measurements.files"),
            "use": "trackproc import-orekit FILE.in -o DIR (stations.csv, initial.json, defaults.toml)"}


def sinex_info(data: bytes, source: str) -> dict:
    """SINEX: the header line, the sites with coordinates and with eccentricities, and the
    stations the reader resolves at the end of the file's data span (positions propagated by
    their velocities, one solution per site)."""
    text = sinex._decode(data, source)
    header = text.split("\n", 1)[0].split()
    blocks = sinex._blocks(text, source)
    estimate = [line.split() for _, line in blocks.get("SOLUTION/ESTIMATE", [])]
    sites = sorted({f[2] for f in estimate if len(f) > 5 and f[1].upper() == "STAX"})
    ecc = sorted({line.split()[0] for _, line in blocks.get("SITE/ECCENTRICITY", []) if line.split()})
    out = {"file": source, "kind": "SINEX " + (header[1] if len(header) > 1 else ""),
           "agency": header[2] if len(header) > 2 else None, "blocks": sorted(blocks),
           "sites_with_coordinates": len(sites), "sites_with_eccentricities": len(ecc)}
    start = end = None
    if len(header) > 6:
        start, end = (sinex.parse_sinex_epoch(header[k], source, 1, "data span") for k in (5, 6))
        out["data_start"] = iso_utc(start, 0) if start is not None else None
        out["data_end"] = iso_utc(end, 0) if end is not None else None
    if sites:
        refs = sorted({f[5] for f in estimate if len(f) > 5 and f[1].upper() == "STAX"})
        out["reference_epochs"] = [refs[0], refs[-1]]
        at = end if end is not None else (start if start is not None else np.datetime64("2000-01-01", "ns"))
        stations = sinex.sinex_stations(data, source, at)
        out["stations_at_data_end"] = len(stations)
        out["sites"] = sites if len(sites) <= 30 else sites[:30] + [f"... {len(sites) - 30} more"]
    return out


def _looks_like_icgem(head: bytes) -> bool:
    return b"begin_of_head" in head or (b"product_type" in head and b"gravity_field" in head)


@contextmanager
def _on_disk(data: bytes, path: str, suffix: str):
    """A real file with ``data``: ``path`` itself, or a temporary copy of stdin (readers that
    take a path: ICGEM, the DopTrack sidecar)."""
    if not is_stdio(path):
        yield Path(path)
        return
    handle, name = tempfile.mkstemp(suffix=suffix)
    try:
        with os.fdopen(handle, "wb") as out:
            out.write(data)
        yield Path(name)
    finally:
        os.unlink(name)


def _gzipped(data: bytes, path: str, source: str) -> dict:
    try:
        with gzip.GzipFile(fileobj=BytesIO(data)) as stream:
            head = stream.read(65536)
    except (OSError, EOFError) as exc:
        raise InputError(f"unreadable gzip data ({exc})", file=source, expected="a complete .gz file") from None
    if _looks_like_icgem(head):
        return icgem_info(data, path, source, suffix=".gfc.gz")
    raise not_known(source, "gzip-compressed data that is not an ICGEM gravity field")


def icgem_info(data: bytes, path: str, source: str, suffix: str = ".gfc") -> dict:
    from trackproc.io.icgem import read_icgem  # start-up: the gravity-field modules

    with _on_disk(data, path, suffix) as file:
        field = read_icgem(file)
    return {"file": source, "kind": "ICGEM gravity field", "model": field.name, "degree": field.degree,
            "order": field.order, "gm_m3_s2": field.gm_m3_s2, "radius_m": field.radius_m,
            "tide_system": field.tide_system, "evaluated_at": field.epoch or None,
            "c20_normalized": float(field.cbar[2, 0]) if field.degree >= 2 else None}


def _looks_like_doptrack_yaml(text: str) -> bool:
    keys = {line.split(":", 1)[0] for line in text.splitlines() if line and not line[0].isspace() and ":" in line}
    return {"satellite", "station", "tracking"} <= keys or {"station", "tracking"} <= keys


def doptrack_yaml_info(data: bytes, path: str, source: str) -> dict:
    with _on_disk(data, path, ".yml") as file:
        doc = load_sidecar(file)
    sat = doc.get("satellite") if isinstance(doc.get("satellite"), dict) else {}
    station = doc.get("station") if isinstance(doc.get("station"), dict) else {}
    tracking = doc.get("tracking") if isinstance(doc.get("tracking"), dict) else {}
    position = station.get("position") if isinstance(station.get("position"), dict) else {}
    tle = sat.get("tle") if isinstance(sat.get("tle"), dict) else {}

    def text(value):
        return iso_utc(value, 6) if hasattr(value, "year") else value

    out = {"file": source, "kind": "DopTrack YAML sidecar (pass metadata)", "satellite": sat.get("name"),
           "norad_id": sat.get("noradid"), "station": station.get("name"),
           "station_lat_deg": position.get("latitude"), "station_lon_deg": position.get("longitude"),
           "station_height_m": position.get("altitude"), "tracking_epoch": text(tracking.get("epoch")),
           "tca": text(tracking.get("tca")), "tca_error_s": tracking.get("tca_error"),
           "fca_hz": tracking.get("fca"), "fca_error_hz": tracking.get("fca_error")}
    if tle.get("line1") and tle.get("line2"):
        parsed = parse_tle(f"{tle['line1']}\n{tle['line2']}\n", f"{source}: satellite.tle")
        out["tle_epoch"] = format_epoch(tle_epoch(parsed))
    return out

"""The steps of ``trackproc batch``: one adapter per pipeline function (ingest, smooth, refine, estimate,
filter).

Adding a step is an adapter and one :func:`~trackproc.pipeline.batch.chain.register` call (see
:func:`refine_step`)::

    def refine_step(ctx: InputContext, opt: dict) -> None:
        ...
        result = refine(table, initial, stations, RefineOptions(cost=opt["cost"], ...), orientation,
                        source=ctx.source)
        ctx.outputs[".refined.json"] = state_json(state, ...).encode("utf-8")
        ctx.numbers.update(converged=..., iterations=..., ...)

    register(Step("refine", "input", refine_step, files=("refine.initial", "refine.eop", "ingest.stations"),
                  table=False))

plus its settings section in :mod:`trackproc.pipeline.batch.schema` (the schema gives the
TOML keys, the flags and the environment variables). The position in
:data:`~trackproc.pipeline.batch.chain.CHAIN` fixes where it runs.

The pipeline modules (numpy, pandas, scipy) are imported inside the adapters, on purpose: a
process must fix its BLAS thread count before numpy loads
(:func:`~trackproc.pipeline.batch.executors.single_thread_blas`, in the driver and in each
worker's initializer, and the fork server preloads this module), and a driver that hands every
task to workers never needs them.
"""

from __future__ import annotations

from pathlib import Path

from trackproc.errors import InputError, ProcessingError
from trackproc.pipeline.batch.chain import InputContext, Step, WindowContext, register

#: Stations tables parsed in this process, by (path, bytes): every input of a batch reads the same one.
_STATIONS: dict = {}


def _stations(ctx) -> dict:
    """The batch's stations table (``ingest.stations``) by name, parsed once per process and
    content (a pure function of the bytes; an invalid table raises each time, as before); a new
    dict each call (the Station values are frozen)."""
    data = ctx.files.get("ingest.stations")
    if data is None:
        return {}
    key = (ctx.paths["ingest.stations"], data)
    if key not in _STATIONS:
        from trackproc.io.stations import parse_stations

        _STATIONS.clear()   # one table at a time: a changed file replaces it
        _STATIONS[key] = parse_stations(data, ctx.paths["ingest.stations"])
    return dict(_STATIONS[key])


#: Kinds in the order their fit is reported as the input's key numbers.
_PRIMARY_KINDS = ("doppler", "range_rate", "range", "elevation", "azimuth")


def _read_input(data: bytes, source: str, opt: dict):
    """Raw samples of one input file's bytes (the dispatch of :func:`trackproc.io.tabular.read_raw`,
    on bytes already read: the driver hashed exactly these)."""
    from trackproc.io import tabular

    if not data.strip():
        raise InputError("empty input", file=source, row=1, found="no data",
                         expected="a CSV, Parquet, Arrow IPC, DopTrack, Orekit .aer or CCSDS TDM file")
    layout = opt["layout"]
    if layout == "auto":
        layout = tabular.detect_layout(data, Path(source).name)
    if layout == "doptrack":
        from trackproc.io.doptrack import read_doptrack

        return read_doptrack(data, source, data_path=Path(source), carrier_hz=opt["carrier_hz"],
                             drop_invalid=opt["drop_invalid"])
    if layout == "aer":
        from trackproc.io.orekit_aer import read_aer

        return read_aer(data, source, drop_invalid=opt["drop_invalid"])
    if layout == "tdm":
        from trackproc.io.tdm import read_tdm

        return read_tdm(data, source, carrier_hz=opt["carrier_hz"], two_way_range=opt["tdm_two_way_range"])
    table = tabular.source_table(data, source)
    if layout == "long" or (layout in ("auto", "table") and tabular.is_long_layout(table)):
        return tabular.read_long(table, drop_invalid=opt["drop_invalid"])
    return tabular.read_wide(table, drop_invalid=opt["drop_invalid"])


def ingest_step(ctx: InputContext, opt: dict) -> None:
    """ingest: the input file -> the canonical pass table (:func:`trackproc.pipeline.ingest.ingest`)."""
    import pyarrow.csv  # noqa: F401 - a plain CSV pass file read whole by Arrow (io.csvtext)

    from trackproc.pipeline.ingest import IngestOptions, ingest

    stations = _stations(ctx)
    raw = _read_input(ctx.data, ctx.source, opt)
    result = ingest([raw], stations, IngestOptions(
        carrier_hz=opt["carrier_hz"], doppler_mode=opt["mode"], max_gap_s=opt["max_gap_s"],
        drop_invalid=opt["drop_invalid"], sigma_range_m=opt["sigma_range_m"],
        sigma_range_rate_m_s=opt["sigma_range_rate_m_s"], sigma_doppler_hz=opt["sigma_doppler_hz"],
        sigma_angle_deg=opt["sigma_angle_deg"]))
    ctx.table = result.table
    ctx.warnings.extend(result.warnings)
    dropped = sum(result.dropped.values())
    if dropped:
        ctx.warnings.append("dropped %d invalid samples: %s" % (
            dropped, ", ".join(f"{reason} {n}" for reason, n in result.dropped.items())))
    ctx.numbers["dropped"] = dropped


def smooth_step(ctx: InputContext, opt: dict) -> None:
    """smooth: polynomial fit of every pass and kind (:func:`trackproc.pipeline.smooth.smooth`).
    Output ``.smooth.json``: the summary of ``trackproc smooth --summary``, the same values in
    compact JSON (one line: a program reads it; ~0.4 ms of CPU a pass less than the indented text)."""
    from trackproc.io.jsonshare import dumps_shared
    from trackproc.io.smoothing_record import fit_summary
    from trackproc.pipeline.smooth import SmoothOptions, smooth

    result = smooth(ctx.table, SmoothOptions(
        degree=opt["degree"], clip=opt["clip"] if opt["clip"] > 0 else None, kinds=list(opt["kinds"]) or None,
        basis=opt["basis"], max_degree=opt["max_degree"], tca_max_gap_s=opt["tca_max_gap_s"]),
        source=ctx.source)
    ctx.table = result.table
    # dumps_compact(summary, sort_keys=False)'s text; the records' float lists encoded here are
    # the pass file's metadata's too (io.jsonshare)
    ctx.outputs[".smooth.json"] = (dumps_shared(result.summary, _summary_encoder()) + "\n").encode("utf-8")
    counts = result.summary["counts"]
    ctx.numbers.update(fits_ok=counts["ok"], fits_suspect=counts["suspect"], fits_failed=counts["failed"])
    records = result.summary["fits"]
    ctx.details["fits"] = [fit_summary(rec) for rec in records]
    fitted = [rec for rec in records if rec["status"] != "failed"]
    fitted.sort(key=lambda r: (_PRIMARY_KINDS.index(r["kind"]) if r["kind"] in _PRIMARY_KINDS else 99,
                               r["tca"]["status"] != "ok" if "tca" in r else True, r["station"], r["pass_id"]))
    if fitted:
        ctx.numbers.update({k: v for k, v in fit_summary(fitted[0]).items()
                            if k in ("kind", "rms", "rms_unit", "tca_utc", "tca_sigma_s", "fca_hz")})
    for f in result.fits:
        if f.status == "failed":
            ctx.warnings.append(f"{f.label}: failed: {f.error}")
        elif f.status == "suspect":
            ctx.warnings.append(f"{f.label}: suspect ({', '.join(f.warnings)})")


#: ``json.dumps(..., allow_nan=False, separators=(",", ":"))``'s encoder (``jsonutil.dumps_compact``).
_SUMMARY_ENCODER = None


def _summary_encoder():
    global _SUMMARY_ENCODER
    if _SUMMARY_ENCODER is None:
        import json

        _SUMMARY_ENCODER = json.JSONEncoder(allow_nan=False, separators=(",", ":"))
    return _SUMMARY_ENCODER


def estimate_step(ctx: WindowContext, opt: dict) -> None:
    """estimate: one orbit and its biases from every pass of the window
    (:func:`trackproc.pipeline.estimate.estimate`)."""
    import numpy as np

    from trackproc.io.eop import earth_orientation
    from trackproc.io.residuals import residuals_bytes
    from trackproc.io.statefile import format_epoch, parse_state_or_tle, state_json
    from trackproc.pipeline.estimate import EstimateOptions, estimate
    from trackproc.pipeline.orbit_source import tle_evaluation_epoch

    orientation, warning = earth_orientation(opt["eop"], opt["dut1"])
    if warning:
        ctx.warnings.append(warning)
    tables = _member_tables(ctx, opt, "no samples left in the window (all flagged by the smoother)")
    initial_bytes, initial_path = ctx.files["estimate.initial"], ctx.paths["estimate.initial"]
    # a TLE: by SGP4 at the solution epoch (default: the first sample)
    at = tle_evaluation_epoch(opt["epoch"], tables, column="estimate.epoch")
    state0 = parse_state_or_tle(initial_bytes, initial_path, orientation, at=at)
    stations = (None if ctx.files.get("ingest.stations") is None
                else _stations(ctx))
    options = EstimateOptions(
        range_bias=opt["range_bias"], doppler_bias=opt["doppler_bias"], doppler_bias_per=opt["doppler_bias_per"],
        angle_bias=opt["angle_bias"], apriori_sigma=dict(opt["apriori_sigma"]), force=opt["force"],
        earth=opt["earth"], range_rate_model=opt["range_rate_model"], max_iterations=opt["max_iterations"],
        clip=opt["clip"] if opt["clip"] > 0 else None, epoch=opt["epoch"], kinds=list(opt["kinds"]) or None)
    result = estimate(tables, state0, stations, options, orientation)
    state = result.state
    ctx.outputs[".json"] = state_json(state, force=opt["force"], eop_source=orientation.source).encode("utf-8")
    meta = {"epoch": format_epoch(state.epoch), "parameters": result.solution.names, "force_model": opt["force"],
            "range_rate_model": result.problem.range_rate_model, "sources": [s for s, _ in tables]}
    ctx.outputs[".residuals.parquet"] = residuals_bytes(result.residuals, meta)
    diag = state.diagnostics
    sig = diag.get("sigma_rtn") or {}
    ctx.numbers.update(
        samples=int(diag["measurements"]), passes=int(sum(t.frame["pass_id"].nunique() for _, t in tables)),
        converged=bool(diag["converged"]), iterations=int(diag["iterations"]), wrms=diag.get("wrms"),
        variance_factor=diag.get("variance_factor"), edited=int(diag.get("edited", 0)),
        epoch_utc=format_epoch(state.epoch), sigma_radial_m=sig.get("radial_m"), sigma_along_m=sig.get("along_m"),
        sigma_cross_m=sig.get("cross_m"), **quality_numbers(result.quality))
    ctx.details["quality"] = result.quality.as_dict()
    ctx.details["parameters"] = {n: {"value": float(v), "sigma": float(s)}
                                 for n, v, s in zip(result.solution.names, np.asarray(result.solution.values),
                                                    np.asarray(result.solution.sigma))}
    ctx.warnings.extend(result.warnings)


def _member_tables(ctx: WindowContext, opt: dict, empty: str) -> list:
    """``[(source, PassTable)]`` of the step's processed inputs, the smoother's flagged samples
    dropped when ``opt["drop_flagged"]``; ``ProcessingError(empty)`` when no sample is left."""
    from trackproc.io.passfile import PassTable, parse_pass_table

    tables = []
    for source, data in ctx.members:
        table = parse_pass_table(data, source)
        frame = table.frame
        if opt["drop_flagged"] and "flag" in frame.columns:
            frame = frame[~frame["flag"].astype(bool)].reset_index(drop=True)
        if len(frame):
            tables.append((source, PassTable(frame, table.meta)))
    if not tables:
        raise ProcessingError(empty)
    return tables


def filter_step(ctx: WindowContext, opt: dict) -> None:
    """filter: every processed input's passes in time order through the sequential filter
    (:func:`trackproc.pipeline.filter.filter_passes`), from the carried state (``ctx.files
    ["filter.carried"]``, the previous run's output) when there is one, else ``filter.initial``;
    the passes not newer than the carried state's last measurement are skipped by the filter.
    Output ``.json``: the filtered state at the last measurement (the next run's start)."""
    import numpy as np

    from trackproc.io.eop import earth_orientation
    from trackproc.io.statefile import format_epoch, parse_state_or_tle, state_json
    from trackproc.pipeline.filter import FilterOptions, filter_passes
    from trackproc.pipeline.od import EstimateOptions
    from trackproc.pipeline.orbit_source import tle_evaluation_epoch

    orientation, warning = earth_orientation(opt["eop"], opt["dut1"])
    if warning:
        ctx.warnings.append(warning)
    tables = _member_tables(ctx, opt, "no samples to filter (all flagged by the smoother)")
    key = "filter.carried" if ctx.files.get("filter.carried") is not None else "filter.initial"
    at = tle_evaluation_epoch(None, tables)
    state0 = parse_state_or_tle(ctx.files[key], ctx.paths[key], orientation, at=at)
    stations = (None if ctx.files.get("ingest.stations") is None
                else _stations(ctx))
    walks = {"doppler_offset": opt["oscillator_noise"]} if opt["oscillator_noise"] else {}
    problem = EstimateOptions(range_bias=opt["range_bias"], doppler_bias=opt["doppler_bias"],
                              apriori_sigma=dict(opt["apriori_sigma"]), force=opt["force"], noise=opt["noise"],
                              range_rate_model=opt["range_rate_model"],
                              kinds=list(opt["kinds"]) or None)
    options = FilterOptions(problem=problem, snc_accel=(opt["snc_accel"],) * 3, bias_walk=walks,
                            edit_sigma=opt["edit_sigma"] if opt["edit_sigma"] > 0 else None)
    result = filter_passes(tables, state0, stations, options, orientation)
    state = result.state
    ctx.outputs[".json"] = state_json(state, force=opt["force"], eop_source=orientation.source).encode("utf-8")
    rec = state.extra["filter"]
    sig = state.diagnostics.get("sigma_rtn") or {}
    ctx.numbers.update(
        samples=int(rec["updates"] + rec["edited"]), edited=int(rec["edited"]), epoch_utc=format_epoch(state.epoch),
        start_utc=rec["first_time"], end_utc=rec["last_measurement"], sigma_radial_m=sig.get("radial_m"),
        sigma_along_m=sig.get("along_m"), sigma_cross_m=sig.get("cross_m"), **quality_numbers(result.quality))
    ctx.details["filter"] = {"initial": ctx.paths[key], "carried_state": rec["carried_state"],
                             "skipped_passes": rec["skipped_passes"], "quality": result.quality.as_dict(),
                             "parameters": {n: {"value": float(v), "sigma": float(e)} for n, v, e in
                                            zip(state.parameters, np.asarray(state.values), np.asarray(state.sigma))}}
    ctx.warnings.extend(w for w in result.warnings if not w.startswith("skipped "))


def quality_numbers(quality) -> dict:
    """A solution's ``quality`` in the summary's numbers: the verdict, the codes of the reasons
    that made it (the whole reasons are in the details) and the decision on the initial orbit."""
    codes = [r["code"] for r in quality.reasons]
    return {"quality": quality.verdict,
            "quality_reasons": ",".join(r["code"] for r in quality.reasons if r["severity"] != "ok"),
            # what became of the initial orbit (methods/estimation/decision.py), when it was decided
            "decision": next((c for c in ("declined", "kept", "replaced", "refused") if c in codes), None)}


def initial_state(data: bytes, path: str, orientation):
    """The stale state of ``refine.initial``: a JSON state file, or a TLE (at its epoch here; refine
    evaluates it by SGP4 at the traverse epoch)."""
    from trackproc.io.statefile import parse_state_or_tle

    return parse_state_or_tle(data, path, orientation)


#: The rule that picks the pass refine uses when an input holds several (docs/batch.md).
REFINE_PASS_RULE = "the pass with the most samples of the kind refine uses (ties: the earliest)"


def refine_pass(table) -> tuple:
    """``(table, chosen, candidates)``: the one pass (station, pass id) refine uses of an input, by
    :data:`REFINE_PASS_RULE`, with all its samples; ``candidates``: every pass of that kind as
    ``{"station", "pass_id", "samples", "start_utc"}``, the chosen first. An input of one pass (or
    without Doppler or range-rate: refine reports that) is returned as it is."""
    import numpy as np

    from trackproc.isotime import iso_utc
    from trackproc.pipeline.refine import RANGE_RATE_KINDS

    # numpy columns, not pandas: the same groups and order (~2 ms a pass of pandas calls)
    kind_of = table.column("kind")
    kinds = set(kind_of.tolist())
    kind = next((k for k in RANGE_RATE_KINDS if k in kinds), None)
    if kind is None:
        return table, None, []
    sel = kind_of == kind
    stations, pass_ids = table.column("station"), table.column("pass_id")
    times = table.column("time")[sel]
    index: dict = {}
    codes = np.array([index.setdefault(key, len(index))
                      for key in zip(stations[sel].tolist(), pass_ids[sel].tolist())], dtype=np.int64)
    counts = np.bincount(codes, minlength=len(index))
    starts = {key: times[codes == j].min() for key, j in index.items()}
    order = sorted(index, key=lambda k: (-int(counts[index[k]]), starts[k], k))
    candidates = [{"station": st, "pass_id": pid, "samples": int(counts[index[(st, pid)]]),
                   "start_utc": iso_utc(starts[(st, pid)], 6)}
                  for st, pid in order]
    station, pass_id = order[0]
    if len(order) == 1:
        return table, order[0], candidates
    keep = (stations == station) & (pass_ids == pass_id)
    return table.take(keep, dict(table.meta or {})), order[0], candidates


def refine_step(ctx: InputContext, opt: dict) -> None:
    """refine: the stale state refined from the input's pass at its traverse point
    (:func:`trackproc.pipeline.refine.refine`, as ``trackproc refine PASS --pass-id ID``); the pass
    with the most samples when the input holds several (:func:`refine_pass`)."""
    from trackproc.io.eop import earth_orientation
    from trackproc.io.statefile import state_json
    from trackproc.pipeline.refine import RefineOptions, refine

    orientation, warning = earth_orientation(opt["eop"], opt["dut1"])
    if warning:
        ctx.warnings.append(warning)
    initial = initial_state(ctx.files["refine.initial"], ctx.paths["refine.initial"], orientation)
    stations = (None if ctx.files.get("ingest.stations") is None
                else _stations(ctx))
    table, chosen, candidates = refine_pass(ctx.table)
    if len(candidates) > 1:
        ctx.warnings.append("%d passes in the input: refined %s/%s (%d samples: %s); not refined: %s" % (
            len(candidates), chosen[0], chosen[1], candidates[0]["samples"], REFINE_PASS_RULE,
            ", ".join(f"{c['station']}/{c['pass_id']} ({c['samples']})" for c in candidates[1:])))
    options = RefineOptions(
        cost=opt["cost"], circular=opt["circular"], circular_tolerance=opt["circular_tolerance"],
        doppler_bias=None if opt["doppler_bias"] == "auto" else opt["doppler_bias"], apriori=opt["apriori"],
        apriori_sigma=dict(opt["apriori_sigma"]), force=opt["force"], earth=opt["earth"],
        range_rate_model=opt["range_rate_model"], max_iterations=opt["max_iterations"],
        clip=opt["clip"] if opt["clip"] > 0 else None, reweight=opt["reweight"])
    try:
        result = refine(table, initial, stations, options, orientation, source=ctx.source)
    except ProcessingError as exc:  # no convergence, too few samples, ...: say which step and pass
        where = f" {chosen[0]}/{chosen[1]}" if chosen else ""
        raise ProcessingError(f"refine{where}: {exc}", exc.diagnostics) from None
    state = result.state if opt["output_epoch"] == "traverse" else result.stale_epoch_state
    ctx.outputs[".refined.json"] = state_json(state, force=opt["force"], eop_source=orientation.source).encode("utf-8")
    diag = result.state.diagnostics
    method = result.state.extra["refinement"]
    sig = diag["sigma_rtn"]
    rms = diag["residual_rms"]
    ctx.numbers.update(
        refined_pass=f"{method['station']}/{method['pass_id']}", traverse_utc=diag["traverse"]["epoch"],
        converged=bool(diag["converged"]), iterations=int(diag["iterations"]), residual_rms=rms["value"],
        residual_rms_unit=rms["unit"], sigma_radial_m=sig["radial_m"], sigma_along_m=sig["along_m"],
        sigma_cross_m=sig["cross_m"], **quality_numbers(result.quality))
    ctx.details["refine"] = {
        "station": method["station"], "pass_id": method["pass_id"], "kind": method["kind"],
        "rule": REFINE_PASS_RULE, "candidates": candidates, "cost": method["cost"], "circular": method["circular"],
        "apriori": method["apriori"], "message": diag["message"], "samples": diag["samples"], "edited": diag["edited"],
        "variance_factor": diag["variance_factor"], "residual_rms": rms, "max_elevation_deg": diag["max_elevation_deg"],
        "traverse": diag["traverse"], "sigma_rtn": sig, "output_epoch": opt["output_epoch"],
        "unobservable": diag["observability"].get("unobservable"),
        "parameters": {n: {"value": float(v), "sigma": float(e)}
                       for n, v, e in zip(result.state.parameters, result.state.values, result.state.sigma)},
        "quality": result.quality.as_dict()}
    ctx.warnings.extend(result.warnings)


register(Step("ingest", "input", ingest_step, files=("ingest.stations",)))
register(Step("smooth", "input", smooth_step))
register(Step("refine", "input", refine_step, files=("refine.initial", "refine.eop", "ingest.stations"), table=False))
register(Step("estimate", "window", estimate_step, files=("estimate.initial", "estimate.eop", "ingest.stations")))
register(Step("filter", "sequence", filter_step, files=("filter.initial", "filter.eop", "ingest.stations")))


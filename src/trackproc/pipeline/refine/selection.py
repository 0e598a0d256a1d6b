"""The pass a refinement uses: the one pass of one station and its kind
(:func:`select_pass`), its smoothed curve (seed 004 eq. 1, :func:`smoothed_curve`) and the
traverse epoch that curve gives (:func:`curve_traverse_epoch`).
"""

from __future__ import annotations

import numpy as np

from trackproc.errors import InputError, ProcessingError
from trackproc.io import smoothing_record
from trackproc.methods.smoothing import SmoothingError, closest_approach
from trackproc.pipeline.refine.options import LINK_MODES, RANGE_RATE_KINDS, RefineOptions, SmoothedCurve
from trackproc.types import PassTable


def select_pass(table: PassTable, options: RefineOptions, source: str) -> tuple[PassTable, str, str, str]:
    if table.n_rows == 0:
        raise InputError("no samples", file=source, expected="a pass file with one Doppler or range-rate pass")
    kind_of = table.column("kind")
    kinds = set(kind_of.tolist())        # not np.unique: a sort of str objects
    if options.kind is not None:
        if options.kind not in RANGE_RATE_KINDS:
            raise InputError("refine uses Doppler or range-rate", column="--kind", found=options.kind,
                             expected=" or ".join(RANGE_RATE_KINDS))
        if options.kind not in kinds:
            raise InputError("no samples of the requested kind", file=source, column="kind",
                             found=", ".join(sorted(kinds)), expected=options.kind)
        kind = options.kind
    else:
        present = [k for k in RANGE_RATE_KINDS if k in kinds]
        if not present:
            raise InputError("no Doppler or range-rate samples", file=source, column="kind",
                             found=", ".join(sorted(kinds)), expected="doppler or range_rate (one Doppler station)")
        kind = present[0]
    rows = kind_of == kind
    pass_of = table.column("pass_id")
    if options.pass_id is not None:
        rows = rows & (pass_of == options.pass_id)
        if not rows.any():
            found = ", ".join(sorted(set(pass_of[kind_of == kind])))
            raise InputError("no such pass", file=source, column="--pass-id", found=options.pass_id,
                             expected=f"one of {found}")
    keys = sorted(set(zip(table.column("station")[rows], pass_of[rows])))
    if len(keys) > 1:
        listed = ", ".join(f"{s}/{p}" for s, p in keys[:8]) + (" ..." if len(keys) > 8 else "")
        raise InputError("more than one pass", file=source, column="pass_id", found=listed,
                         expected="one pass of one station; choose one with --pass-id")
    station, pass_id = keys[0]
    mode = (table.meta or {}).get("doppler_mode") or "one-way"
    if mode not in LINK_MODES:
        raise InputError("unknown link mode", file=source, column="doppler_mode", found=mode,
                         expected=" or ".join(LINK_MODES))
    return table.take(rows, dict(table.meta or {})), kind, station, pass_id


def smoothed_curve(sub: PassTable, kind: str, station: str, pass_id: str, source: str) -> SmoothedCurve:
    """The smoothed polynomial of the pass: from the ``smoothing`` metadata when ``smooth`` made
    it (seed 004 eq. 1), else fitted here with ``smooth``'s defaults; and its closest approach."""
    meta = sub.meta or {}
    mode = str(meta.get("doppler_mode") or "one-way")
    times = sub.column("time")
    rec = smoothing_record.find_fit_record(meta, station, pass_id, kind)
    if rec is not None:
        fit = smoothing_record.fit_from_record(rec)
        epoch = smoothing_record.record_epoch(rec)
        used = ~np.asarray(sub.column("flag")).astype(bool) if "flag" in sub.column_names else np.ones(sub.n_rows, bool)
        t_used = (times[used] - epoch).astype(np.int64) * 1e-9
        tca, note = None, ""
        try:
            tca = closest_approach(fit, kind, mode)
        except SmoothingError as exc:
            note = str(exc)
        if isinstance(rec.get("tca"), dict) and rec["tca"].get("status") == "not_observed":
            note = str(rec["tca"].get("error") or "closest approach not observed")
        return SmoothedCurve(fit=fit, epoch=epoch, kind=kind, tca=tca, tca_note=note, source="metadata",
                             used_t_s=np.sort(t_used))
    if smoothing_record.output_of(meta) == "grid":
        raise InputError("a smoothed grid without its polynomial", file=source, column="smoothing",
                         expected=f"the smoothing record of {station}/{pass_id}/{kind} in the metadata")
    # start-up: smooth only for a pass that was not smoothed
    from trackproc.pipeline.smooth import SmoothOptions, smooth

    try:
        result = smooth(PassTable(sub.frame[["time", "station", "pass_id", "kind", "value", "sigma"]], meta),
                        SmoothOptions(), source=source)
    except ProcessingError as exc:
        raise ProcessingError(f"the pass cannot be smoothed: {exc}") from None
    pf = result.fits[0]
    if pf.fit is None:
        raise ProcessingError(f"the pass cannot be smoothed: {pf.error}")
    epoch = np.datetime64(pf.epoch_utc, "ns")
    tca, note = pf.tca, pf.tca_error or ""
    if tca is None:
        try:
            tca = closest_approach(pf.fit, kind, mode)
        except SmoothingError as exc:
            note = str(exc)
    return SmoothedCurve(fit=pf.fit, epoch=epoch, kind=kind, tca=tca, tca_note=note, source="fitted here",
                         used_t_s=np.sort(pf.t_s[pf.fit.used]))


def curve_traverse_epoch(curve: SmoothedCurve, warnings: list, override=None) -> tuple[np.datetime64, str]:
    if override is not None:
        return np.datetime64(override, "ns"), "the refined orbit's own zero range-rate (iterated)"
    if curve.tca is not None:
        t = curve.tca.t_s
        how = curve.tca.definition
        if curve.tca_note:
            warnings.append(f"the closest approach of the smoothed curve is not well observed ({curve.tca_note}); "
                            "the traverse epoch rests on the polynomial there")
    else:
        a, b = curve.fit.domain_s
        t = 0.5 * (a + b)
        how = "middle of the pass (no closest approach in the smoothed curve)"
        warnings.append(f"no traverse point in the pass ({curve.tca_note}); the state is given at mid-pass")
    return curve.epoch + np.timedelta64(int(round(t * 1e9)), "ns"), how

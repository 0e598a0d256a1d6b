"""``trackproc identify``: which catalogue object a pass belongs to (issue 18 item 4).

Every candidate TLE is compared with the pass (:func:`trackproc.pipeline.compare.compare`: SGP4
at the samples, each pass's own offset and drift fitted and removed -- the transmitter's frequency
is not known). Candidates are ranked by their weighted residual sum of squares ``S_i`` (after
removal, over all passes and kinds).

Likelihood ratios. With Gaussian residuals of a common unknown scale, the profile likelihood of
candidate ``i`` is ``L_i ∝ S_i^(-n/2)``. Residuals of a TLE against a pass are not white: the
TLE's error is a smooth function of time, so ``n`` samples carry far fewer independent pieces of
information. ``n`` is therefore replaced by an effective sample size from the best candidate's
residuals, ``n_eff = n / τ`` with ``τ = 1 + 2 Σ ρ_k`` their integrated autocorrelation time
(Geyer's initial positive sequence; ``n_eff = n`` for white residuals), giving

    ln LR_i = −(n_eff / 2) ln(S_i / S_best)        (LR_best = 1)

The verdict is ``decisive`` when every runner-up has ``LR < 1/100`` (Jeffreys' "decisive" odds),
otherwise ``ambiguous``, naming the runners-up above that level. The likelihood ratio compares
the candidates given; it says nothing about an object missing from the catalogue: ``rms_over_sigma``
of the best candidate says whether it fits at all. It ranks *predictions*: a TLE is itself
kilometres off after a day, so objects whose TLEs differ by less than that cannot be told apart
by any pass, and the best-fitting prediction need not carry the right label.
"""

from __future__ import annotations

import logging
import math

import numpy as np

from trackproc.errors import InputError, ProcessingError
from trackproc.io.tle import parse_tle
from trackproc.pipeline.compare import CompareOptions, compare, fit_trend
from trackproc.pipeline.orbit_source import OrbitInput

log = logging.getLogger("trackproc")

#: Likelihood ratio below which a runner-up is excluded (Jeffreys: odds above 100:1 are decisive).
DECISIVE_LR = 0.01


def parse_catalogue(text: str, source: str = "<catalogue>") -> list:
    """TLEs of a catalogue file: element-line pairs, each optionally after a name line (as
    CelesTrak and Space-Track serve them). Each TLE is checked by :func:`trackproc.io.tle.parse_tle`
    (errors name the file and its line)."""
    lines = text.splitlines()
    tles, i, n = [], 0, len(lines)
    seen: dict = {}
    repeats: list = []

    def element(k, number):
        return k < n and lines[k].startswith(number + " ") and len(lines[k].rstrip()) == 69

    while i < n:
        if not lines[i].strip():
            i += 1
            continue
        start = i
        name = None
        if not element(i, "1"):
            name, i = lines[i], i + 1
        if not (element(i, "1") and element(i + 1, "2")):
            bad = i + 1 if element(i, "1") else i      # the line that is not what it should be
            raise InputError("not a TLE (expected an optional name line, then lines 1 and 2 of 69 characters)",
                             file=source, row=bad + 1, found=(lines[bad][:30] if bad < n else "end of file"),
                             expected=f"a line '{'2' if bad > i else '1'} ...' of 69 characters")
        block = ([name] if name is not None else []) + [lines[i], lines[i + 1]]
        try:
            tle = parse_tle("\n".join(block), source)
        except InputError as exc:
            # parse_tle counts the block's rows from 1: give the catalogue's row
            raise InputError(exc.detail, file=source, row=start + (exc.row or 1), column=exc.column,
                             found=exc.found, expected=exc.expected) from None
        previous = seen.get(tle.satnum)
        if previous is None:
            seen[tle.satnum] = (start + 1, tle)
        else:
            same = (previous[1].line1[18:68], previous[1].line2[8:68]) == (tle.line1[18:68], tle.line2[8:68])
            repeats.append((tle.satnum, previous[0], start + 1, same))
        tles.append(tle)
        i += 2
    if not tles:
        raise InputError("no TLE in the catalogue", file=source, expected="one or more TLEs")
    if repeats:
        satnum, first, again, same = repeats[0]
        log.warning("%s: %d element set(s) repeat a catalogue number already listed (first: %s at rows %d and %d%s); "
                    "each is ranked as a candidate of its own", source, len(repeats), satnum, first, again,
                    ", the same elements" if same else ", different elements")
    return tles


def _autocorrelation(series, max_lag: int) -> np.ndarray:
    """Pooled autocorrelation ``rho_k``, k = 0..max_lag, of residual series (passes and kinds)."""
    num = np.zeros(max_lag + 1)
    den = 0.0
    for r in series:
        r = np.asarray(r, float)
        den += float(np.dot(r, r))
        for k in range(min(max_lag, len(r) - 1) + 1):
            num[k] += float(np.dot(r[k:], r[:len(r) - k]))
    return num / den if den > 0 else np.eye(1, max_lag + 1)[0]


def integrated_autocorrelation_time(series, max_lag: int = 1000) -> float:
    """``tau = 1 + 2 sum_k rho_k`` summed by Geyer's initial positive sequence (pairs
    ``rho_{2m} + rho_{2m+1}`` while positive): the factor by which correlated residuals hold fewer
    independent samples (``n_eff = n / tau``). Geyer (1992), Statistical Science 7, 473."""
    longest = max((len(r) for r in series), default=1)
    rho = _autocorrelation(series, min(max_lag, max(longest - 1, 1)))
    tau = -1.0                               # 1 + 2 sum_{k>=1} rho_k = -1 + 2 sum_{m} (rho_2m + rho_2m+1)
    for m in range(len(rho) // 2):
        pair = rho[2 * m] + rho[2 * m + 1]
        if pair <= 0:
            break
        tau += 2 * pair
    return max(tau, 1.0)


def identify(table, tles: list, eop=None, remove: str = "offset+drift", range_rate_model: str = "doppler",
             earth: str = "wgs84") -> dict:
    """Rank ``tles`` by their fit to ``table``; the result dict (candidates best first, verdict)."""
    options = CompareOptions(remove=remove, force="sgp4", earth=earth, range_rate_model=range_rate_model)
    rows = []
    series = {}
    for tle in tles:
        label = f"{tle.satnum}" + (f" ({tle.name})" if tle.name else "")
        try:
            res, summary = compare(table, OrbitInput(tle=tle, source=label), options, eop)
        except ProcessingError as exc:
            rows.append({"satnum": tle.satnum, "name": tle.name, "failed": str(exc)})
            continue
        wss, n, after_all = 0.0, 0, []
        t_s = (res["time"] - res["time"].min()).dt.total_seconds().to_numpy()
        for _, group in res.groupby(["pass_id", "kind"], sort=True):
            idx = group.index.to_numpy()
            _, after = fit_trend(t_s[idx] - t_s[idx].min(), group["residual"].to_numpy(),
                                 group["sigma"].to_numpy(), remove)
            w = after / group["sigma"].to_numpy()
            wss += float(np.dot(w, w))
            n += len(idx)
            after_all.append(w)
        series[tle.satnum + (tle.name or "")] = after_all
        rows.append({"satnum": tle.satnum, "name": tle.name, "samples": n, "weighted_ss": wss,
                     "rms_over_sigma": math.sqrt(wss / n),
                     "passes": [{k: p[k] for k in ("pass_id", "kind", "rms", "unit") if k in p} |
                                {k: p[k] for k in ("offset", "drift") if k in p} for p in summary["passes"]],
                     "_key": tle.satnum + (tle.name or "")})
    ok = sorted((r for r in rows if "failed" not in r), key=lambda r: (r["weighted_ss"], r["satnum"]))
    if not ok:
        raise ProcessingError("no candidate could be evaluated: " + "; ".join(r["failed"] for r in rows))
    best = ok[0]
    tau = integrated_autocorrelation_time(series[best["_key"]])
    n_eff = best["samples"] / tau
    for r in ok:
        r["ln_likelihood_ratio"] = -0.5 * n_eff * math.log(r["weighted_ss"] / best["weighted_ss"]) + 0.0
        r["likelihood_ratio"] = math.exp(r["ln_likelihood_ratio"])
        r.pop("_key")
    runners = [r for r in ok[1:] if r["likelihood_ratio"] >= DECISIVE_LR]
    verdict = "decisive" if not runners else "ambiguous"
    return {
        "generator": "trackproc identify",
        "verdict": verdict,
        "best": {"satnum": best["satnum"], "name": best["name"]},
        "runners_up": [{"satnum": r["satnum"], "name": r["name"], "likelihood_ratio": r["likelihood_ratio"]}
                       for r in runners],
        "effective_samples": n_eff, "autocorrelation_time_samples": tau,
        "method": ("SGP4 per candidate, per-pass offset+drift removed; ln LR = -(n_eff/2) ln(S_i/S_best), "
                   "n_eff = n / tau, tau the integrated autocorrelation time of the best candidate's residuals; decisive when every runner-up "
                   f"has LR < {DECISIVE_LR:g}") if remove == "offset+drift" else f"as above, removing {remove}",
        "candidates": ok + [r for r in rows if "failed" in r],
    }

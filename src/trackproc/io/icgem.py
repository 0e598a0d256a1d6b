"""Reader of gravity-field models in the ICGEM ``.gfc`` format (ICGEM 1.0 and 2.0).

The International Centre for Global Earth Models exchange format (Barthelmes & Förste,
"The ICGEM-format", GFZ Potsdam, 2011; ICGEM-Format-2023): a free-text preamble, a header
between ``begin_of_head`` and ``end_of_head`` (``earth_gravity_constant``, ``radius``,
``max_degree``, ``tide_system``, ``norm``, ``errors``, ``modelname``), then one line per
coefficient::

    gfc   L M  C  S  [sigma_C sigma_S]                     static coefficient
    gfct  L M  C  S  [sigma_C sigma_S]  t0 [t1]            value at the reference epoch t0
    trnd  L M  C  S  [sigma_C sigma_S]  [t0 t1]            drift per year  (``dot`` in old files)
    acos  L M  C  S  [sigma_C sigma_S]  [t0 t1] period_y   cosine amplitude
    asin  L M  C  S  [sigma_C sigma_S]  [t0 t1] period_y   sine amplitude

(dates ``yyyymmdd`` or ``yyyymmdd.hhmm``; ICGEM 2.0 adds the validity interval ``t0 t1`` to
each time-variable line). A coefficient at a date t is (the EIGEN-6S header's own rule,
evaluated as Orekit's ``ICGEMFormatReader`` does)::

    G(t) = gfct + trnd (t - t0) + Σ_p [acos_p cos(2π (t - t0)/p) + asin_p sin(2π (t - t0)/p)]

with ``t - t0`` in Julian years (365.25 d). Coefficients above the requested degree/order are
skipped while reading. A malformed file raises :class:`~trackproc.errors.InputError` naming
the file, the line and what was expected. ``.gz`` files are read transparently.
"""

from __future__ import annotations

import gzip
import json
import math
import zlib
from importlib import resources
from pathlib import Path

import numpy as np

from trackproc.dynamics.forces.gravity_field import GravityField
from trackproc.constants import MAX_GRAVITY_DEGREE
from trackproc.errors import InputError
from trackproc.io import table_cache

__all__ = ["read_icgem", "default_field_path", "load_field", "DEFAULT_FIELD_NAME"]

#: The field shipped in the package (trackproc/data): EIGEN-6S to degree/order 70 with its
#: time-variable terms (degree <= 50), unchanged lines of GFZ's file (see README "Forces").
DEFAULT_FIELD_NAME = "eigen-6s-70.gfc.gz"
_JULIAN_YEAR_D = 365.25
_HEADER_KEYS = ("earth_gravity_constant", "radius", "max_degree", "tide_system", "norm", "errors", "modelname",
                "product_type", "format")


def default_field_path() -> Path:
    """Path of the gravity field shipped with the package."""
    return Path(str(resources.files("trackproc") / "data" / DEFAULT_FIELD_NAME))


def _open(path: Path):
    if path.suffix == ".gz":
        return gzip.open(path, "rt", encoding="latin-1")
    return open(path, encoding="latin-1")


#: A header's max_degree above this is refused before anything is allocated: the highest-degree
#: model ICGEM serves (Earth2014, degree 10800).
MAX_HEADER_DEGREE = 10800
#: An Earth field's constants (refusing km for m, km^3/s^2 for m^3/s^2 or another body's field):
#: GM within 0.1 % of 3.986004418e14 m^3/s^2, the reference radius 6.3e6 to 6.4e6 m.
_EARTH_GM = (3.982e14, 3.990e14)
_EARTH_RADIUS_M = (6.3e6, 6.4e6)


def _lines(fh, fname: str):
    """``enumerate(fh, 1)`` with a damaged file (a compressed stream that ends early, a corrupt
    block) an :class:`InputError` naming the file and the last line read."""
    lineno = 0
    try:
        for lineno, line in enumerate(fh, 1):
            yield lineno, line
    except (EOFError, zlib.error, gzip.BadGzipFile, OSError, UnicodeDecodeError) as exc:
        raise InputError(f"the file is damaged or cut short ({type(exc).__name__}: {exc})", file=fname,
                         row=lineno + 1, expected="a complete ICGEM file (a .gz file decompressed to its end)") from None


def check_request(degree, order, fname: str) -> None:
    """The requested degree and order: at most :data:`~trackproc.constants.MAX_GRAVITY_DEGREE`."""
    if degree is not None and not 0 <= degree <= MAX_GRAVITY_DEGREE:
        raise InputError(f"gravity degree {degree} requested", file=fname, column="--gravity", found=degree,
                         expected=f"a degree from 0 to {MAX_GRAVITY_DEGREE} (terms beyond it are below 1e-13 of "
                                  "the central term at 200 km altitude)")
    if order is not None and degree is not None and not 0 <= order <= degree:
        raise InputError(f"gravity order {order} requested", file=fname, column="--gravity", found=order,
                         expected=f"0 <= order <= degree {degree}")


def check_field(static: dict, terms: list, nmax: int, order, lmax: int, fname: str, rows: dict) -> None:
    """The parsed coefficients against the header and the degree used: each finite and below 1
    in magnitude (fully normalised coefficients of degree >= 1 are), and every coefficient of
    degree 2 to ``nmax`` (orders up to ``order``) present as a ``gfc`` or ``gfct`` line -- a
    missing one would silently count as zero (a file cut short, a header promising more than it
    holds). Degrees 0 and 1 may be omitted (C00 = 1; no degree-1 terms in a geocentric frame)."""
    for (n, m), (c, s) in static.items():
        if not (math.isfinite(c) and math.isfinite(s)) or (n >= 1 and (abs(c) >= 1 or abs(s) >= 1)):
            raise InputError("implausible coefficient", file=fname, row=rows.get((n, m)), column=f"L={n} M={m}",
                             found=f"C {c!r}, S {s!r}", expected="finite fully normalised values, |C|, |S| < 1")
    seen = set()
    for kind, n, m, c, s, t0, t1, period in terms:
        if not (math.isfinite(c) and math.isfinite(s)):
            raise InputError(f"non-finite {kind} coefficient", file=fname, column=f"L={n} M={m}",
                             found=f"C {c!r}, S {s!r}", expected="finite values")
        key = (kind, n, m, t0, t1, period)      # ICGEM 2.0 repeats a term only for another interval
        if key in seen:
            raise InputError(f"{kind} term of L={n} M={m} listed twice (it would be added twice)", file=fname,
                             column=f"L={n} M={m}", found=f"two {kind} lines for the same interval"
                             + (f" and period {period:g} y" if period else ""),
                             expected=f"one {kind} line per L, M and validity interval")
        seen.add(key)
    present = set(static) | {(n, m) for kind, n, m, *_ in terms if kind == "gfct"}
    mmax = nmax if order is None else order
    for n in range(2, nmax + 1):
        for m in range(min(n, mmax) + 1):
            if (n, m) not in present:
                held = max((k[0] for k in present), default=0)
                raise InputError(f"coefficient L={n} M={m} missing", file=fname, column=f"L={n} M={m}",
                                 found=f"coefficients up to degree {held} (header max_degree {lmax})",
                                 expected=f"every coefficient up to the degree used ({nmax}): lower --gravity "
                                          "or give a complete file")


_DATES: dict = {}     # date text -> days: a file repeats a few dates on thousands of lines


def _date_days(text: str, where) -> float:
    """``yyyymmdd`` or ``yyyymmdd.hhmm`` -> days since 1970-01-01 (UTC, as float)."""
    if text in _DATES:
        return _DATES[text]
    try:
        whole, _, frac = text.partition(".")
        day = np.datetime64(f"{whole[:4]}-{whole[4:6]}-{whole[6:8]}", "D")
        hours = int(frac[:2]) if frac[:2] else 0
        minutes = int(frac[2:4]) if frac[2:4] else 0
    except (ValueError, IndexError):
        raise InputError("bad date", **where, found=text, expected="yyyymmdd or yyyymmdd.hhmm") from None
    _DATES[text] = float(day.astype("int64")) + (hours * 60 + minutes) / 1440.0
    return _DATES[text]


def read_icgem(path, degree: int | None = None, order: int | None = None, date=None) -> GravityField:
    """Read an ICGEM ``.gfc`` file into a :class:`GravityField` at ``date``.

    Parameters
    ----------
    path : file path (``.gfc`` or ``.gfc.gz``).
    degree, order : truncation on read (default: the file's ``max_degree``; order = degree).
    date : UTC ``datetime64`` (or ISO text) at which the time-variable terms are evaluated;
        default the reference epoch of the file's ``gfct`` lines (the static part).
    """
    path = Path(path)
    fname = str(path)
    if not path.is_file():
        raise InputError("gravity field file not found", file=fname, expected="an ICGEM .gfc file")
    when = None
    if date is not None:
        d = np.datetime64(str(date).rstrip("Zz") if isinstance(date, str) else date, "s")
        when = float(d.astype("int64")) / 86400.0
    check_request(degree, order, fname)
    header, static, terms, lmax = _parsed(path, fname, degree, order)
    nmax = lmax if degree is None else degree
    check_request(nmax, order, fname)
    check_field(static, terms, nmax, order, lmax, fname, {})
    cbar = np.zeros((nmax + 1, nmax + 1))
    sbar = np.zeros((nmax + 1, nmax + 1))
    for (n, m), (c, s) in static.items():
        cbar[n, m] += c
        sbar[n, m] += s
    epoch_text = _add_time_variable(terms, cbar, sbar, when, fname)
    if order is not None:
        cbar[:, order + 1:] = 0.0
        sbar[:, order + 1:] = 0.0
    if nmax >= 0 and cbar[0, 0] == 0.0:
        cbar[0, 0] = 1.0                 # C00 = 1 by definition (some files omit the line)
    name = header.get("modelname", path.name)
    return GravityField(gm_m3_s2=float(header["earth_gravity_constant"]), radius_m=float(header["radius"]),
                        cbar=cbar, sbar=sbar, name=name, tide_system=header.get("tide_system", "unknown"),
                        source=path.name, epoch=epoch_text)


def _parse(path: Path, fname: str, degree: int | None = None, order: int | None = None):
    """The header, the static coefficients ``{(L, M): (C, S)}``, the time-variable terms
    ``[(kind, L, M, C, S, t0, t1, period)]`` and ``max_degree`` of an ICGEM file, line by line."""
    header: dict[str, str] = {}
    in_header = False
    static: dict = {}
    terms: list = []                     # (kind, n, m, c, s, t0, t1, period)
    lmax = None
    rows: dict = {}
    with _open(path) as fh:
        for lineno, line in _lines(fh, fname):
            words = line.split()
            if not words:
                continue
            key = words[0].lower()
            where = {"file": fname, "row": lineno}
            if key == "begin_of_head":
                in_header = True
                continue
            if key == "end_of_head":
                in_header = False
                lmax = _check_header(header, fname, lineno)
                if degree is not None and degree > lmax:
                    raise InputError(f"degree {degree} requested", file=fname, found=f"max_degree {lmax}",
                                     expected=f"a degree <= {lmax}")
                continue
            if in_header or lmax is None:
                if key in _HEADER_KEYS and len(words) >= 2:
                    header[key] = words[1]
                continue
            if key not in ("gfc", "gfct", "trnd", "dot", "acos", "asin"):
                raise InputError("unknown line key", **where, found=words[0],
                                 expected="gfc, gfct, trnd, dot, acos or asin")
            try:
                n, m = int(words[1]), int(words[2])
                c, s = float(words[3].replace("D", "E").replace("d", "e")), float(words[4].replace("D", "E").replace("d", "e"))
            except (ValueError, IndexError):
                raise InputError("bad coefficient line", **where, found=line.strip()[:80],
                                 expected="key L M C S [sigma_C sigma_S] ...") from None
            if not (0 <= m <= n) or n > lmax:
                raise InputError("bad degree/order", **where, found=f"L={n} M={m}",
                                 expected=f"0 <= M <= L <= max_degree {lmax}")
            if (degree is not None and n > degree) or (order is not None and m > order):
                continue
            rest = words[5 + header["_nsig"]:]
            if key == "gfc":
                if (n, m) in static and static[(n, m)] != (c, s):
                    raise InputError(f"coefficient L={n} M={m} listed twice with different values", **where,
                                     found=f"C {c!r}, S {s!r} (row {rows[(n, m)]}: C {static[(n, m)][0]!r}, "
                                           f"S {static[(n, m)][1]!r})", expected="one gfc line per L, M")
                static[(n, m)] = (c, s)
                rows.setdefault((n, m), lineno)
                continue
            if key == "gfct":
                if not rest:
                    raise InputError("gfct line without its reference epoch", **where, expected="t0 (yyyymmdd)")
                t0 = _date_days(rest[0], where)
                t1 = _date_days(rest[1], where) if len(rest) > 1 else None
                terms.append(("gfct", n, m, c, s, t0, t1, None))
            elif key in ("trnd", "dot"):
                t0 = _date_days(rest[0], where) if len(rest) >= 2 else None
                t1 = _date_days(rest[1], where) if len(rest) >= 2 else None
                terms.append(("trnd", n, m, c, s, t0, t1, None))
            else:
                if not rest:
                    raise InputError(f"{key} line without its period", **where, expected="period in years")
                try:
                    period = float(rest[-1])
                except ValueError:
                    raise InputError(f"bad {key} period", **where, found=rest[-1], expected="period in years") from None
                if not period > 0:
                    raise InputError(f"bad {key} period", **where, found=rest[-1], expected="a positive period in years")
                t0 = _date_days(rest[0], where) if len(rest) >= 3 else None
                t1 = _date_days(rest[1], where) if len(rest) >= 3 else None
                terms.append((key, n, m, c, s, t0, t1, period))
    if lmax is None:
        raise InputError("no ICGEM header", file=fname, expected="a header ending in end_of_head")
    return header, static, terms, lmax


def _parsed(path: Path, fname: str, degree: int | None, order: int | None):
    """:func:`_parse` through the user cache (io/table_cache.py): the whole file parsed once per
    content, then truncated to ``degree`` x ``order`` as reading it with them would have."""
    arrays = table_cache.cached_arrays("icgem", path, lambda: _to_arrays(*_parse(path, fname)), parser=__file__)
    lmax = int(arrays["lmax"])
    if degree is not None and degree > lmax:
        raise InputError(f"degree {degree} requested", file=fname, found=f"max_degree {lmax}",
                         expected=f"a degree <= {lmax}")
    kept = {}
    for part in ("static", "term"):
        nm = arrays[f"{part}_nm"]
        keep = (nm[:, 0] <= (lmax if degree is None else degree)) & (nm[:, 1] <= (lmax if order is None else order))
        kept.update({name: value[keep] for name, value in arrays.items() if name.startswith(part)})
    return _from_arrays(json.loads(str(arrays["header"])), lmax, **kept)


_TERM_KINDS = ("gfct", "trnd", "acos", "asin")


def _to_arrays(header, static, terms, lmax) -> dict:
    nan = float("nan")
    return {"header": np.array(json.dumps(header)), "lmax": np.array(lmax),
              "static_nm": np.array(list(static.keys()), dtype=np.int64).reshape(-1, 2),
              "static_cs": np.array(list(static.values()), dtype=np.float64).reshape(-1, 2),
              "term_kind": np.array([_TERM_KINDS.index(t[0]) for t in terms], dtype=np.int8),
              "term_nm": np.array([t[1:3] for t in terms], dtype=np.int64).reshape(-1, 2),
              "term_values": np.array([[nan if v is None else v for v in t[3:]] for t in terms],
                                      dtype=np.float64).reshape(-1, 5)}


def _from_arrays(header, lmax, static_nm, static_cs, term_kind, term_nm, term_values):
    """Back to :func:`_parse`'s Python values (floats, ints, None), bit for bit."""
    static = {(n, m): (c, s) for (n, m), (c, s) in zip(static_nm.tolist(), static_cs.tolist())}
    terms = []
    for kind, (n, m), values in zip(term_kind.tolist(), term_nm.tolist(), term_values.tolist()):
        c, s = values[:2]
        t0, t1, period = (None if v != v else v for v in values[2:])      # NaN stored for None
        terms.append((_TERM_KINDS[kind], n, m, c, s, t0, t1, period))
    return header, static, terms, lmax


def _check_header(header: dict, fname: str, lineno: int) -> int:
    for key in ("earth_gravity_constant", "radius", "max_degree"):
        if key not in header:
            raise InputError(f"header keyword {key} missing", file=fname, row=lineno,
                             expected="earth_gravity_constant, radius and max_degree in the header")
    try:
        gm, radius, lmax = float(header["earth_gravity_constant"]), float(header["radius"]), int(header["max_degree"])
    except ValueError:
        raise InputError("bad header value", file=fname, row=lineno,
                         found={k: header[k] for k in ("earth_gravity_constant", "radius", "max_degree")},
                         expected="numbers") from None
    if not (gm > 0 and radius > 0 and lmax >= 0):
        raise InputError("bad header value", file=fname, row=lineno, found=f"GM {gm}, radius {radius}, max_degree {lmax}",
                         expected="positive GM and radius, max_degree >= 0")
    if not _EARTH_GM[0] <= gm <= _EARTH_GM[1]:
        raise InputError("implausible earth_gravity_constant", file=fname, row=lineno, column="earth_gravity_constant",
                         found=header["earth_gravity_constant"],
                         expected=f"the Earth's GM in m^3/s^2, {_EARTH_GM[0]:.4g} to {_EARTH_GM[1]:.4g}")
    if not _EARTH_RADIUS_M[0] <= radius <= _EARTH_RADIUS_M[1]:
        raise InputError("implausible radius", file=fname, row=lineno, column="radius", found=header["radius"],
                         expected=f"the Earth's reference radius in metres, {_EARTH_RADIUS_M[0]:.3g} to "
                                  f"{_EARTH_RADIUS_M[1]:.3g}")
    if lmax > MAX_HEADER_DEGREE:
        raise InputError("implausible max_degree", file=fname, row=lineno, column="max_degree", found=lmax,
                         expected=f"at most {MAX_HEADER_DEGREE} (the highest-degree model published, Earth2014)")
    norm = header.get("norm", "fully_normalized").lower()
    if norm not in ("fully_normalized", "fully_normalised"):
        raise InputError("unsupported normalisation", file=fname, row=lineno, found=norm, expected="fully_normalized")
    header["_nsig"] = 0 if header.get("errors", "formal").lower() == "no" else 2
    return lmax


def _add_time_variable(terms, cbar, sbar, when, fname) -> str:
    """Add gfct + trnd + periodic terms evaluated at ``when`` (days since 1970) into the arrays.

    ICGEM 1.0: a trnd/acos/asin line refers to the gfct of its (L, M) (its t0). ICGEM 2.0:
    each line has its validity interval [t0, t1); the lines whose interval holds the date count.
    Without a date, the epoch of the gfct lines is used (their static value).
    """
    if not terms:
        return ""
    ref = {}
    for kind, n, m, c, s, t0, t1, _ in terms:
        if kind == "gfct" and (n, m) not in ref:
            ref[(n, m)] = t0
    if when is None:
        when = min(ref.values()) if ref else 0.0
    for kind, n, m, c, s, t0, t1, period in terms:
        if t0 is not None and t1 is not None and not (t0 <= when < t1):
            continue
        base = t0 if t0 is not None else ref.get((n, m))
        if base is None:
            raise InputError(f"{kind} term of L={n} M={m} has no reference epoch (no gfct line)", file=fname,
                             expected="a gfct line for every time-variable coefficient")
        dt_y = (when - base) / _JULIAN_YEAR_D
        if kind == "gfct":
            k = 1.0
        elif kind == "trnd":
            k = dt_y
        elif kind == "acos":
            k = np.cos(2 * np.pi * dt_y / period)
        else:
            k = np.sin(2 * np.pi * dt_y / period)
        cbar[n, m] += k * c
        sbar[n, m] += k * s
    return str(np.datetime64(int(round(when * 86400)), "s")) + "Z"


def load_field(path=None, degree: int = 20, order: int | None = None, date=None) -> GravityField:
    """The field of ``path`` (default: the shipped EIGEN-6S) to ``degree`` x ``order`` at ``date``."""
    return read_icgem(default_field_path() if path is None else path, degree, order, date)

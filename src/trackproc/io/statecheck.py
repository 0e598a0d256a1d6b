"""Whether a state file is certainly one :func:`trackproc.io.statefile.parse_state` accepts,
without numpy (standard library only): the batch driver's up-front check of ``refine.initial``
(``pipeline/batch/run.py``) in a process that otherwise never imports numpy (~0.15 s of CPU with
the state file reader's own imports).

:func:`certainly_valid` is conservative: True only for a GCRF state file whose every field passes
the reader's checks with a margin (epoch ``YYYY-MM-DDTHH:MM:SS[.f]Z`` in years whose UTC ERFA
converts without a "dubious year" warning; a covariance whose correlation matrix has a Cholesky
factor, hence no eigenvalue below the reader's bound). Anything else, a TLE, another frame, an
offset, a value near a bound, an error, answers False: the caller then parses the file with the
reader itself, which gives its one-line error or its warning exactly as before.
"""

from __future__ import annotations

import datetime
import json
import math
import re

from trackproc.constants import MU_EARTH

#: ``types.checks.ORBIT_RADIUS_RANGE_M`` and ``MIN_SPEED_FRACTION`` (equal: tests/io/test_statecheck.py)
ORBIT_RADIUS_RANGE_M = (6_356_000.0, 1.5e9)
MIN_SPEED_FRACTION = 0.05
#: ``types.state.STATE_PARAMETERS``
STATE_PARAMETERS = ("x", "y", "z", "vx", "vy", "vz")
#: Years whose UTC dates ERFA's dtf2d (pyerfa 2.0.1.5) converts with status 0: not before 1960,
#: not past its leap-second table's reach (2028); checked by the tests against the installed ERFA.
YEARS = (1972, 2027)
#: Relative margin kept from every bound of the reader (its own arithmetic is numpy's, not ours).
MARGIN = 1e-6
_EPOCH = re.compile(r"(\d{4})-(\d{2})-(\d{2})T(\d{2}):(\d{2}):(\d{2})(?:\.(\d{1,9}))?Z\Z")
_GCRF = ("GCRF", "GCRS", "ICRF")
_LARGEST = 64          # parameters; beyond, the reader's eigenvalue round-off is not bounded here


def certainly_valid(data: bytes) -> bool:
    """True when ``data`` (a state file's bytes) is certainly accepted by ``parse_state`` in the
    GCRF frame, without a warning; False when unsure (see the module docstring)."""
    try:
        return _valid(data)
    except Exception:  # noqa: BLE001 - any surprise: the reader decides
        return False


def _numbers(value, n: int | None) -> list | None:
    """``value`` as floats when it is a list of ``n`` finite JSON numbers, else None."""
    if not isinstance(value, list) or (n is not None and len(value) != n):
        return None
    if not all(type(x) in (int, float) for x in value):
        return None
    out = [float(x) for x in value]
    return out if all(math.isfinite(x) for x in out) else None


def _valid(data: bytes) -> bool:
    if data.lstrip()[:1] != b"{":
        return False
    doc = json.loads(data)
    if not isinstance(doc, dict):
        return False
    version = doc.get("schema_version", 1)
    if type(version) is not int or version > 1:
        return False
    epoch = doc.get("epoch")
    match = _EPOCH.match(epoch) if isinstance(epoch, str) else None
    if match is None:
        return False
    year, month, day, hour, minute, second = (int(g) for g in match.groups()[:6])
    if not YEARS[0] <= year <= YEARS[1] or hour > 23 or minute > 59 or second > 59:
        return False
    datetime.date(year, month, day)                      # ValueError (False) for no such day
    frame = doc.get("frame")
    if not isinstance(frame, str) or frame.strip().upper().replace("-", "").replace("_", "") not in _GCRF:
        return False
    r = _numbers(doc.get("position_m"), 3)
    v = _numbers(doc.get("velocity_m_s"), 3)
    if r is None or v is None or not _orbit(r, v):
        return False
    for key in ("constants", "diagnostics"):
        if not isinstance(doc.get(key) or {}, dict):
            return False
    force = doc.get("force_model")
    if force is not None and not isinstance(force, str):
        return False
    return _parameters(doc, r + v)


def _orbit(r: list, v: list) -> bool:
    """``types.checks.check_orbit_state`` (and the reader's |r| > 100 km), with :data:`MARGIN`."""
    radius, speed = math.sqrt(sum(x * x for x in r)), math.sqrt(sum(x * x for x in v))
    low, high = ORBIT_RADIUS_RANGE_M
    if not (low * (1 + MARGIN) <= radius <= high * (1 - MARGIN)):
        return False
    escape = math.sqrt(2.0 * MU_EARTH / radius)
    return MIN_SPEED_FRACTION * escape / math.sqrt(2.0) * (1 + MARGIN) <= speed <= escape * (1 - MARGIN)


def _parameters(doc: dict, rv: list) -> bool:
    """``parameters``, ``values``, ``sigma`` and ``covariance`` as the reader checks them."""
    params = doc.get("parameters")
    present = [doc.get(key) is not None for key in ("values", "sigma", "covariance")]
    if params is None:
        return not any(present)
    if not isinstance(params, list) or not all(isinstance(p, str) and p for p in params):
        return False
    n = len(params)
    if len(set(params)) != n or n > _LARGEST:
        return False
    values = sigma = cov = None
    if present[0]:
        values = _numbers(doc["values"], n)
        if values is None:
            return False
        if all(p in params for p in STATE_PARAMETERS):
            # the reader: allclose(values[x..vz], rv, rtol=0, atol=1e-6)
            if any(abs(values[params.index(p)] - x) > 0.5e-6 for p, x in zip(STATE_PARAMETERS, rv)):
                return False
    if present[1]:
        sigma = _numbers(doc["sigma"], n)
        if sigma is None or any(s < 0 for s in sigma):
            return False
    if present[2]:
        rows = doc["covariance"]
        if not isinstance(rows, list) or len(rows) != n or n == 0:
            return False
        cov = [_numbers(row, n) for row in rows]
        if any(row is None for row in cov) or not _positive_definite(cov):
            return False
    if sigma is not None and cov is not None:
        # the reader: allclose(sigma, sqrt(diag), rtol=1e-6, atol=0)
        if any(abs(s - math.sqrt(cov[i][i])) > 0.5e-6 * math.sqrt(cov[i][i]) for i, s in enumerate(sigma)):
            return False
    return True


def _positive_definite(cov: list) -> bool:
    """The reader's ``check_covariance`` passes: positive variances, the correlation matrix
    symmetric within half its 1e-9 and with a Cholesky factor (pivots above 1e-9, so no
    eigenvalue of it below the reader's -1e-10 however numpy's ``eigvalsh`` rounds: for a matrix
    of unit diagonal and n <= 64, the factor's backward error is below ~n² 1e-16)."""
    n = len(cov)
    diag = [cov[i][i] for i in range(n)]
    if any(d <= 0 for d in diag):
        return False
    scale = [math.sqrt(d) for d in diag]
    corr = [[cov[i][j] / (scale[i] * scale[j]) for j in range(n)] for i in range(n)]
    for i in range(n):
        for j in range(i):
            if abs(corr[i][j] - corr[j][i]) > 0.5e-9:
                return False
    a = [[0.5 * (corr[i][j] + corr[j][i]) for j in range(n)] for i in range(n)]
    low = [[0.0] * n for _ in range(n)]
    for j in range(n):                                   # Cholesky-Banachiewicz (Golub & Van Loan, Alg. 4.2.1)
        pivot = a[j][j] - sum(low[j][k] ** 2 for k in range(j))
        if not pivot > 1e-9:
            return False
        low[j][j] = math.sqrt(pivot)
        for i in range(j + 1, n):
            low[i][j] = (a[i][j] - sum(low[i][k] * low[j][k] for k in range(j))) / low[j][j]
    return True

"""State files (JSON): an orbit state, its estimated parameters and error matrix, in GCRF.

Layout (README "Data contract", "State file"), keys in this order when written::

    {"schema_version": 1,
     "epoch": "2026-03-20T09:30:00.000Z",           # UTC, ISO 8601
     "frame": "GCRF",                                 # read: GCRF, EME2000/J2000, TEME, ITRF
     "position_m": [x, y, z], "velocity_m_s": [vx, vy, vz],
     "parameters": ["x", "y", "z", "vx", "vy", "vz", "range_bias:ZHY"],   # optional
     "values": [...], "sigma": [...],                 # optional, follow "parameters"
     "covariance": [[...], ...],                      # optional, rows/columns follow "parameters"
     "force_model": "two-body+J2",
     "constants": {"mu_m3_s2": ..., "j2": ..., "re_m": ...},
     "earth_orientation": "IERS finals2000A finals.all",
     "diagnostics": {...},
     ...}                                             # other keys are kept (State.extra)

Reading validates every field (an :class:`~trackproc.errors.InputError` names the file and
the field as ``column``), converts the state to GCRF (frame bias for EME2000, SGP4's TEME
through ITRF, ITRF with the Earth orientation given), and with it the values and the
covariance of the six state parameters (``J C Jᵀ`` with the exact Jacobian of the frame
transform, which is linear in position and velocity). Writing is deterministic (fixed key
order, shortest round-trip floats) and atomic, always in GCRF.

Units: metres, m/s; the covariance in the units of the parameters (m², m²/s, m²/s², ...).

A little over 400 lines: one format, its field checks, frame conversions and writer together
(:mod:`trackproc.io.statecheck` is the standard-library pre-check a batch's driver uses).
"""

from __future__ import annotations

import json
import math
from typing import Optional

import numpy as np

from trackproc.io.jsonutil import dumps_indented, json_ready
from trackproc.constants import MU_EARTH, force_model_constants
from trackproc.dynamics import frames
from trackproc.dynamics.kepler import classical_elements
from trackproc.dynamics.timescales import datetime64_to_jd_utc
from trackproc.errors import InputError
from trackproc.isotime import iso_utc as format_epoch  # noqa: F401  (the state file's epoch text)
from trackproc.io.atomic import is_stdio, read_input_bytes, write_text
from trackproc.io.validate import check_orbit_state
from trackproc.types.epoch import parse_epoch  # noqa: F401  (re-exported)
from trackproc.types.state import STATE_PARAMETERS, State  # noqa: F401  (re-exported)

SCHEMA_VERSION = 1
#: Frames accepted on read (aliases map to these), converted to GCRF.
FRAMES = ("GCRF", "EME2000", "J2000", "TEME", "ITRF")
#: File label of each force model key (the CLI's ``--force`` values).
FORCE_LABELS = {"two-body": "two-body", "j2": "two-body+J2"}
_FORCE_KEYS = {"two-body": "two-body", "twobody": "two-body", "keplerian": "two-body",
               "j2": "j2", "two-body+j2": "j2", "twobody+j2": "j2"}
_KNOWN_KEYS = ("schema_version", "epoch", "frame", "position_m", "velocity_m_s", "parameters", "values",
               "sigma", "covariance", "force_model", "constants", "earth_orientation", "diagnostics",
               "elements")   # derived on output (osculating elements), never read back
#: Tolerances of the covariance checks (relative to the largest diagonal scale).
_SYMMETRY_RTOL = 1e-9
_PSD_RTOL = 1e-10


# --------------------------------------------------------------------------- epochs


# --------------------------------------------------------------------------- reading

def _vector(doc: dict, key: str, n: int | None, file: str, required: bool = True) -> Optional[np.ndarray]:
    if key not in doc or doc[key] is None:
        if required:
            raise InputError("missing field", file=file, column=key,
                             expected=f"a list of {n} numbers" if n else "a list of numbers")
        return None
    value = doc[key]
    ok = isinstance(value, list) and all(isinstance(x, (int, float)) and not isinstance(x, bool) for x in value)
    if not ok or (n is not None and len(value) != n):
        raise InputError("wrong type or length", file=file, column=key, found=_short(value),
                         expected=f"a list of {n} numbers" if n else "a list of numbers")
    try:
        out = np.asarray(value, float)
    except OverflowError:                                # an integer beyond a float's range
        out = np.array([math.inf])
    if not np.all(np.isfinite(out)):
        raise InputError("non-finite number", file=file, column=key, found=_short(value), expected="finite numbers")
    return out


def _short(value) -> str:
    text = json.dumps(value) if not isinstance(value, str) else value
    return text if len(text) <= 80 else text[:77] + "..."


def _frame_key(frame, file: str) -> str:
    if not isinstance(frame, str):
        raise InputError("wrong type", file=file, column="frame", found=_short(frame),
                         expected="one of " + ", ".join(FRAMES))
    key = frame.strip().upper().replace("-", "").replace("_", "")
    aliases = {"GCRF": "GCRF", "GCRS": "GCRF", "ICRF": "GCRF", "EME2000": "EME2000", "J2000": "EME2000",
               "TEME": "TEME", "ITRF": "ITRF", "ITRS": "ITRF", "ECEF": "ITRF"}
    if key not in aliases:
        raise InputError("unknown frame", file=file, column="frame", found=frame,
                         expected="one of " + ", ".join(FRAMES))
    return aliases[key]


def force_key(label) -> Optional[str]:
    """The ``--force`` key of a force-model label (``"two-body+J2"`` -> ``"j2"``), or None."""
    if not isinstance(label, str):
        return None
    return _FORCE_KEYS.get(label.strip().lower().replace(" ", ""))


def parse_state(data: bytes | str, source: str = "<state>", eop=None) -> State:
    """The :class:`State` in the JSON text ``data``; see the module docstring."""
    file = source
    doc = _state_document(data, file)
    if "epoch" not in doc:
        raise InputError("missing field", file=file, column="epoch", expected="an ISO 8601 UTC time")
    epoch = parse_epoch(doc["epoch"], file=file)
    if "frame" not in doc:
        raise InputError("missing field", file=file, column="frame", expected="one of " + ", ".join(FRAMES))
    frame = _frame_key(doc["frame"], file)
    r = _vector(doc, "position_m", 3, file)
    v = _vector(doc, "velocity_m_s", 3, file)
    if np.linalg.norm(r) < 1.0e5:
        raise InputError("position is not an orbit", file=file, column="position_m", found=_short(doc["position_m"]),
                         expected="metres from the Earth's centre (|r| > 100 km; kilometres given?)")
    if frame != "ITRF":   # an Earth-fixed velocity lacks the rotation: checked after conversion
        check_orbit_state(r, v, file=file)

    params = doc.get("parameters")
    if params is not None:
        _check_parameter_names(params, file)
    n = len(params) if params is not None else None
    values = _vector(doc, "values", n, file, required=False)
    sigma = _vector(doc, "sigma", n, file, required=False)
    cov = _covariance(doc, n, file)
    if params is None and any(x is not None for x in (values, sigma, cov)):
        size = next(len(x) for x in (values, sigma, cov) if x is not None)
        if size != 6:
            raise InputError("missing field", file=file, column="parameters",
                             expected="the parameter names that values/sigma/covariance follow")
        params = list(STATE_PARAMETERS)
        for name, x in (("values", values), ("sigma", sigma), ("covariance", cov)):
            if x is not None and len(x) != 6:
                raise InputError("wrong length", file=file, column=name, found=len(x), expected="6 (x .. vz)")
    if sigma is not None and np.any(sigma < 0):
        raise InputError("negative sigma", file=file, column="sigma", found=_short(doc["sigma"]),
                         expected="sigmas >= 0")
    if sigma is not None and cov is not None:
        diag = np.sqrt(np.diag(cov))
        if not np.allclose(sigma, diag, rtol=1e-6, atol=0.0):
            i = int(np.argmax(np.abs(sigma - diag)))
            raise InputError("sigma disagrees with the covariance diagonal", file=file, column="sigma",
                             found=f"{params[i]}: {sigma[i]!r} vs sqrt(covariance) {diag[i]!r}",
                             expected="sigma = sqrt(diag(covariance))")
    if params is None:
        params = list(STATE_PARAMETERS)
    index = {p: i for i, p in enumerate(params)}
    state_idx = [index[p] for p in STATE_PARAMETERS if p in index]
    if values is not None and len(state_idx) == 6:
        idx = [index[p] for p in STATE_PARAMETERS]
        rv = np.concatenate([r, v])
        if not np.allclose(values[idx], rv, rtol=0.0, atol=1e-6):
            raise InputError("values of x..vz disagree with position_m/velocity_m_s", file=file, column="values",
                             found=_short(doc["values"]), expected="the same state in both places")

    jd1, jd2 = datetime64_to_jd_utc(epoch)
    jd1, jd2 = float(jd1), float(jd2)
    constants = _object_field(doc, "constants", file)
    diagnostics = _object_field(doc, "diagnostics", file)
    force = doc.get("force_model")
    if force is not None and not isinstance(force, str):
        raise InputError("wrong type", file=file, column="force_model", found=_short(force),
                         expected="a force model name such as two-body+J2")

    if frame != "GCRF":
        jac = _frame_jacobian(frame, jd1, jd2, eop)
        rv_g = jac @ np.concatenate([r, v])
        r, v = rv_g[:3], rv_g[3:]
        if len(state_idx) == 6:
            idx = [index[p] for p in STATE_PARAMETERS]
            full = np.eye(len(params))
            full[np.ix_(idx, idx)] = jac
            if values is not None:
                values = values.copy()
                values[idx] = rv_g
            if cov is None and sigma is not None:
                cov = np.diag(sigma ** 2)
            if cov is not None:
                cov = full @ cov @ full.T
                cov = 0.5 * (cov + cov.T)
                sigma = np.sqrt(np.clip(np.diag(cov), 0.0, None))
        elif any(p in index for p in STATE_PARAMETERS) and (cov is not None or sigma is not None):
            raise InputError("a covariance over part of x..vz cannot be converted from " + frame,
                             file=file, column="parameters", found=_short(params),
                             expected="all of x, y, z, vx, vy, vz, or frame GCRF")

    if frame == "ITRF":
        check_orbit_state(r, v, file=file)
    eop_source = doc.get("earth_orientation")
    extra = {k: doc[k] for k in doc if k not in _KNOWN_KEYS}
    if frame != "GCRF":
        extra["converted_from_frame"] = frame
    return State(epoch=epoch, jd_utc=(jd1, jd2), r_m=r, v_m_s=v, parameters=list(params), values=values,
                 sigma=sigma, covariance=cov, force_model=force_key(force) or force, constants=dict(constants),
                 eop_source=eop_source if isinstance(eop_source, str) else None,
                 diagnostics=dict(diagnostics), extra=extra, source=source)


def _state_document(data: bytes | str, file: str) -> dict:
    """The JSON object of a state file, of a schema version this reader knows."""
    try:
        doc = json.loads(data)
    except (json.JSONDecodeError, UnicodeDecodeError) as exc:
        row = getattr(exc, "lineno", None)
        raise InputError(f"not valid JSON ({getattr(exc, 'msg', exc)})", file=file, row=row,
                         expected="a JSON state file") from None
    except RecursionError:
        raise InputError("JSON nested too deeply", file=file, expected="a JSON state file (a few levels of nesting)") from None
    if not isinstance(doc, dict):
        raise InputError("not a state file", file=file, found=type(doc).__name__, expected="a JSON object")
    version = doc.get("schema_version", SCHEMA_VERSION)
    if not isinstance(version, int) or isinstance(version, bool) or version > SCHEMA_VERSION:
        raise InputError("unsupported state file version", file=file, column="schema_version", found=version,
                         expected=f"an integer <= {SCHEMA_VERSION}")
    return doc


def _object_field(doc: dict, key: str, file: str) -> dict:
    """An optional field that must be a JSON object ({} when absent or empty)."""
    value = doc.get(key) or {}
    if not isinstance(value, dict):
        raise InputError("wrong type", file=file, column=key, found=_short(value), expected="an object")
    return value


def _check_parameter_names(params, file: str) -> None:
    """``parameters``: a list of distinct, non-empty names."""
    if not isinstance(params, list) or not all(isinstance(p, str) and p for p in params):
        raise InputError("wrong type", file=file, column="parameters", found=_short(params),
                         expected="a list of parameter names")
    dup = sorted({p for p in params if params.count(p) > 1})
    if dup:
        raise InputError("duplicate parameter", file=file, column="parameters", found=dup[0],
                         expected="each name once")


def _covariance(doc: dict, n: int | None, file: str) -> Optional[np.ndarray]:
    if doc.get("covariance") is None:
        return None
    value = doc["covariance"]
    ok = (isinstance(value, list) and value and all(isinstance(row, list) for row in value)
          and all(isinstance(x, (int, float)) and not isinstance(x, bool) for row in value for x in row))
    size = n if n is not None else (len(value) if isinstance(value, list) else 0)
    expected = f"a {size} x {size} list of lists of numbers (rows and columns follow 'parameters')"
    if not ok or len(value) != size or any(len(row) != size for row in value):
        raise InputError("wrong type or shape", file=file, column="covariance", found=_short(value), expected=expected)
    try:
        cov = np.asarray(value, float)
    except OverflowError:                                # an integer beyond a float's range
        cov = np.array([math.inf])
    if not np.all(np.isfinite(cov)):
        raise InputError("non-finite number", file=file, column="covariance", found=_short(value),
                         expected="finite numbers")
    check_covariance(cov, file=file)
    return cov


def check_covariance(cov: np.ndarray, *, file: str | None = None, column: str = "covariance") -> None:
    """Symmetric and positive semi-definite, within round-off of the matrix's own scale.

    Symmetry is judged after scaling by ``sqrt(diag)`` (a correlation matrix; |Δ| ≤ 1e-9),
    definiteness by the smallest eigenvalue of that correlation matrix (≥ -1e-10).
    """
    diag = np.diag(cov)
    if np.any(diag < 0):
        i = int(np.argmin(diag))
        raise InputError("negative variance", file=file, column=column, found=f"covariance[{i}][{i}] = {diag[i]!r}",
                         expected="a positive semi-definite matrix")
    scale = np.sqrt(np.where(diag > 0, diag, 1.0))
    corr = cov / np.outer(scale, scale)
    asym = np.abs(corr - corr.T)
    if asym.max(initial=0.0) > _SYMMETRY_RTOL:
        i, j = np.unravel_index(int(np.argmax(asym)), asym.shape)
        raise InputError("covariance is not symmetric", file=file, column=column,
                         found=f"[{i}][{j}] = {cov[i, j]!r} vs [{j}][{i}] = {cov[j, i]!r}",
                         expected="a symmetric matrix")
    lowest = float(np.linalg.eigvalsh(0.5 * (corr + corr.T)).min()) if corr.size else 0.0
    if lowest < -_PSD_RTOL * max(1.0, float(np.abs(corr).max(initial=0.0))):
        raise InputError("covariance is not positive semi-definite", file=file, column=column,
                         found=f"smallest eigenvalue of the correlation matrix {lowest:.3g}",
                         expected="a positive semi-definite matrix")


def _frame_jacobian(frame: str, jd1: float, jd2: float, eop) -> np.ndarray:
    """6 × 6 matrix of the (linear) transform of (r, v) from ``frame`` to GCRF at a UTC date."""
    basis = np.eye(6)
    r_g, v_g = frames.to_gcrf(frame, basis[:, :3], basis[:, 3:], jd1, jd2, eop)
    return np.concatenate([r_g, v_g], axis=1).T


def read_state(path: str, eop=None) -> State:
    """Read a state file (or ``-`` for stdin); see :func:`parse_state`."""
    source = "<stdin>" if is_stdio(path) else str(path)
    return parse_state(read_input_bytes(path), source, eop)


def read_state_or_tle(path: str, eop=None, at=None) -> State:
    """A JSON state file, or a TLE (2 or 3 lines) converted by SGP4 at its epoch or at ``at``."""
    source = "<stdin>" if is_stdio(path) else str(path)
    return parse_state_or_tle(read_input_bytes(path), source, eop, at)


def is_state_json(data: bytes) -> bool:
    """A JSON state file (its bytes start with ``{``) rather than a TLE: the one rule that tells
    ``STATE|TLE`` arguments apart (:func:`parse_state_or_tle`, ``pipeline.orbit_source.read_orbit``)."""
    return data.lstrip()[:1] == b"{"


def parse_state_or_tle(data: bytes, source: str, eop=None, at=None) -> State:
    """The bytes of a JSON state file (they start with ``{``), or of a TLE (2 or 3 lines) converted
    by SGP4 at its epoch or at ``at`` (:func:`is_state_json` tells them apart)."""
    if is_state_json(data):
        return parse_state(data, source, eop)
    from trackproc.io.tle import parse_tle, tle_state   # here: io.tle builds a State from this module

    return tle_state(parse_tle(data.decode("utf-8", errors="replace"), source), at=at, eop=eop)


# --------------------------------------------------------------------------- writing

def orbital_elements(state: State) -> dict:
    """Osculating classical elements of the state, for people (degrees); derived, never read back."""
    mu = (state.constants or {}).get("mu_m3_s2", MU_EARTH)
    return classical_elements(state.r_m, state.v_m_s, mu)


def state_document(state: State, force: str | None = None, eop_source: str | None = None) -> dict:
    """The JSON object of ``state`` (GCRF), keys in the documented order.

    ``force`` (a ``--force`` key) and ``eop_source`` override the state's own; the force
    model's constants come from :func:`trackproc.constants.force_model_constants`.
    """
    force = force if force is not None else state.force_model
    key = force_key(FORCE_LABELS.get(force, force)) if force is not None else None
    doc = {"schema_version": SCHEMA_VERSION, "epoch": format_epoch(state.epoch), "frame": "GCRF",
           "position_m": state.r_m, "velocity_m_s": state.v_m_s, "elements": orbital_elements(state),
           "parameters": list(state.parameters)}
    values = state.values
    if values is None:
        values = np.full(len(state.parameters), np.nan)
        index = {p: i for i, p in enumerate(state.parameters)}
        for p, x in zip(STATE_PARAMETERS, state.rv):
            if p in index:
                values[index[p]] = x
        if np.isnan(values).any():
            values = None
    if values is not None:
        doc["values"] = values
    sigma = state.sigma
    if sigma is None and state.covariance is not None:
        sigma = np.sqrt(np.clip(np.diag(state.covariance), 0.0, None))
    if sigma is not None:
        doc["sigma"] = sigma
    if state.covariance is not None:
        doc["covariance"] = state.covariance
    if key is not None:
        doc["force_model"] = FORCE_LABELS[key]
        doc["constants"] = force_model_constants(key)
    elif force is not None:
        doc["force_model"] = force
        if state.constants:
            doc["constants"] = state.constants
    source = eop_source if eop_source is not None else state.eop_source
    if source is not None:
        doc["earth_orientation"] = source
    if "quality" in state.extra:
        doc["quality"] = state.extra["quality"]           # the verdict first, for a reader and for cron
    doc["diagnostics"] = state.diagnostics or {}
    for k in sorted(state.extra):
        if k not in doc:
            doc[k] = state.extra[k]
    return json_ready(doc)


def state_json(state: State, force: str | None = None, eop_source: str | None = None) -> str:
    """Deterministic JSON text of ``state``: one top-level key per line, vectors on one line,
    the covariance one row per line, floats as the shortest text that reads back exactly."""
    doc = state_document(state, force, eop_source)
    lines = []
    for key, value in doc.items():
        if key == "covariance":
            body = "[\n" + ",\n".join("    " + json.dumps(row, allow_nan=False) for row in value) + "\n  ]"
        elif isinstance(value, dict) and value:
            body = dumps_indented(value, 2).replace("\n", "\n  ")
        else:
            body = json.dumps(value, allow_nan=False)
        lines.append(f"  {json.dumps(key)}: {body}")
    return "{\n" + ",\n".join(lines) + "\n}\n"


def write_state(state: State, path: str, force: str | None = None, eop_source: str | None = None) -> None:
    """Write ``state`` atomically to ``path`` (``-`` = stdout) as GCRF JSON."""
    write_text(path, state_json(state, force, eop_source))

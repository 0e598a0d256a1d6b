"""JSON output shared by every command: plain Python values, NaN/Inf as null, stable text."""

from __future__ import annotations

import json
import math
import sys


def json_ready(value):
    """A JSON-ready copy: numpy scalars/arrays to Python, NaN/Inf to None (JSON has neither),
    tuples to lists, datetime64 to ISO 8601 UTC with Z."""
    kind = type(value)
    if kind is float:                         # the common leaves first (issue 19: thousands per pass)
        return value if math.isfinite(value) else None
    if kind is str or kind is int or kind is bool or value is None:
        return value
    # numpy as the caller loaded it: a process without numpy (a batch's driver) has no numpy value
    np = sys.modules.get("numpy")
    if np is not None and kind is np.ndarray and value.dtype.kind == "f" and np.isfinite(value).all():
        return value.tolist()                 # nothing to replace: Python floats already
    if isinstance(value, dict):
        return {str(k): json_ready(v) for k, v in value.items()}
    if kind is list and all(type(v) is float for v in value) and all(map(math.isfinite, value)):
        return value[:]                       # a row of finite floats (a covariance row): as it is
    if isinstance(value, (list, tuple)):
        return [json_ready(v) for v in value]
    if np is not None:
        if isinstance(value, np.ndarray):
            return json_ready(value.tolist())
        if isinstance(value, np.datetime64):
            from trackproc.isotime import iso_utc   # a leaf that imports numpy: loaded here already

            return iso_utc(value, 9)
        if isinstance(value, np.generic):
            return json_ready(value.item())
    if isinstance(value, float) and not math.isfinite(value):
        return None
    return value


def dumps(value, indent: int | None = 2) -> str:
    """Deterministic JSON text (keys sorted) of :func:`json_ready` of ``value``, newline-terminated.

    With an indent, in one walk: a plain value (a ``str``, finite ``float``, ``int``, ``bool``,
    ``None``, ``list``, ``tuple``, or ``dict`` with ``str`` keys) is emitted as it is, which is
    what ``json_ready`` would return for it; only the other values (numpy, non-finite floats,
    other keys) go through ``json_ready`` where they are met. A batch's summary holds results that
    the workers made JSON-ready already: converting them again cost as much as the emission."""
    if indent is None:
        return json.dumps(json_ready(value), sort_keys=True, allow_nan=False) + "\n"
    out: list = []
    try:
        _emit(value, out, "\n", " " * indent, True, json_ready)
    except (_NotPlain, ValueError):
        return dumps_indented(json_ready(value), indent, sort_keys=True) + "\n"
    out.append("\n")
    return "".join(out)


def dumps_compact(value, sort_keys: bool = True, ready: bool = False) -> str:
    """:func:`dumps` without whitespace, newline-terminated: the same values (the same float text,
    ``float.__repr__``), all encoded by the standard library's C encoder, several times faster
    than the indented text (for the files a batch writes per input, which a program reads).
    ``ready``: ``value`` is :func:`json_ready`'s output already (not converted again)."""
    return json.dumps(value if ready else json_ready(value), sort_keys=sort_keys, allow_nan=False,
                      separators=(",", ":")) + "\n"


class _NotPlain(Exception):
    """A value :func:`dumps_indented` leaves to ``json.dumps`` (another type, a non-finite float)."""


#: The C encoder of the standard library: compact, the shortest float text (``float.__repr__``).
_COMPACT = json.JSONEncoder(allow_nan=False, separators=(",", ":"))
_STRING = json.encoder.encode_basestring_ascii
#: The types the C encoder writes as :func:`_emit` does (exact types: ``json_ready`` leaves them).
_SCALARS = frozenset((str, int, float, bool, type(None)))
_STR = frozenset((str,))
#: (item separator, sort_keys) -> the C encoder of one flat container at that depth.
_FLAT: dict = {}


def _not_plain(value):
    raise _NotPlain


def _flat_encoder(separator: str, sort_keys: bool):
    """The standard library's C encoder (what ``json.dumps`` uses without an indent) with
    ``separator`` between items: a container of scalars at one depth of an indented text in one
    call. Its float text is ``float.__repr__``, its strings those of ``encode_basestring_ascii``,
    as :func:`_emit`'s; ``json.JSONEncoder.encode`` where the C encoder is missing."""
    encode = _FLAT.get((separator, sort_keys))
    if encode is None:
        make = json.encoder.c_make_encoder
        if make is None:
            encode = json.JSONEncoder(allow_nan=False, sort_keys=sort_keys, check_circular=False,
                                      separators=(separator, ": ")).encode
        else:
            chunks = make(None, _not_plain, _STRING, None, ": ", separator, sort_keys, False, False)
            encode = lambda value: "".join(chunks(value, 0))  # noqa: E731
        encode = _FLAT[(separator, sort_keys)] = encode
    return encode


def dumps_indented(value, indent: int = 2, sort_keys: bool = False) -> str:
    """``json.dumps(value, indent=indent, sort_keys=sort_keys, allow_nan=False)``, the same text,
    several times faster on the outputs of :func:`json_ready`: with an indent the standard library
    encodes in Python, element by element (9 % of a batch's CPU went there), whereas here every
    container of scalars (residuals, covariance rows, a fit's numbers) is encoded by its C encoder
    at once. Any other value (a non-finite float, a type ``json_ready`` does not give) goes to
    ``json.dumps``, which gives its text or its error."""
    out: list = []
    try:
        _emit(value, out, "\n", " " * indent, sort_keys, None)
    except (_NotPlain, ValueError):
        return json.dumps(value, indent=indent, sort_keys=sort_keys, allow_nan=False)
    return "".join(out)


def _emit(value, out: list, newline: str, step: str, sort_keys: bool, convert) -> None:
    """Append the indented text of ``value`` (at the depth ``newline`` gives) to ``out``.
    ``convert``: None, a value that is not plain raises :class:`_NotPlain`; else the function
    (``json_ready``) whose result is emitted in its place."""
    kind = type(value)
    if kind is str:
        out.append(_STRING(value))
    elif value is None:
        out.append("null")
    elif value is True:
        out.append("true")
    elif value is False:
        out.append("false")
    elif kind is float:
        if math.isfinite(value):
            out.append(float.__repr__(value))
        elif convert is None:
            raise _NotPlain                                 # json.dumps raises its ValueError
        else:
            out.append("null")                              # json_ready's None
    elif kind is int:
        out.append(int.__repr__(value))
    elif kind is list or kind is tuple:
        if not value:
            out.append("[]")
            return
        inner = newline + step
        if _SCALARS.issuperset(map(type, value)):
            try:
                text = _flat_encoder("," + inner, sort_keys)(value)
            except ValueError:                              # a non-finite float: item by item
                if convert is None:
                    raise _NotPlain from None
            else:
                out.append("[" + inner + text[1:-1] + newline + "]")
                return
        elif all(type(row) is list and row and all(type(v) is float or type(v) is int for v in row) for row in value):
            # a matrix of numbers (a covariance): all its rows by one call of the C encoder
            try:
                rows = _COMPACT.encode(value)[2:-2].split("],[")
            except ValueError:
                if convert is None:
                    raise _NotPlain from None
            else:
                deeper = inner + step
                out.append("[" + inner + ("," + inner).join("[" + deeper + ("," + deeper).join(row.split(",")) + inner
                                                            + "]" for row in rows) + newline + "]")
                return
        out.append("[")
        for i, item in enumerate(value):
            out.append("," + inner if i else inner)
            _emit(item, out, inner, step, sort_keys, convert)
        out.append(newline + "]")
    elif kind is dict:
        if not value:
            out.append("{}")
            return
        if not _STR.issuperset(map(type, value)):
            if convert is None:
                raise _NotPlain
            _emit(convert(value), out, newline, step, sort_keys, convert)   # its keys as json_ready's str()
            return
        inner = newline + step
        if _SCALARS.issuperset(map(type, value.values())):
            try:
                text = _flat_encoder("," + inner, sort_keys)(value)
            except ValueError:
                if convert is None:
                    raise _NotPlain from None
            else:
                out.append("{" + inner + text[1:-1] + newline + "}")
                return
        out.append("{")
        first = True
        for key, item in (sorted(value.items()) if sort_keys else value.items()):
            head = (inner if first else "," + inner) + _STRING(key) + ": "
            first = False
            kind = type(item)
            if kind is str:                                 # the scalars here, without a call
                out.append(head + _STRING(item))
            elif kind is float and math.isfinite(item):
                out.append(head + float.__repr__(item))
            elif kind is int:
                out.append(head + int.__repr__(item))
            else:
                out.append(head)
                _emit(item, out, inner, step, sort_keys, convert)
        out.append(newline + "}")
    elif convert is None:
        raise _NotPlain
    else:
        ready = convert(value)
        if ready is value:                                  # a type json_ready leaves as it is
            raise _NotPlain
        _emit(ready, out, newline, step, sort_keys, convert)

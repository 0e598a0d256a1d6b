"""Compact JSON text of a value whose long float lists are encoded once and shared between texts.

A smoothed pass is written twice with the same smoothing records: ``.smooth.json`` (keys in
insertion order) and the pass file's metadata (keys sorted, :func:`trackproc.io.passfile.meta_json`).
The records' covariance matrices and coefficients are most of either text, and their float text
(``float.__repr__``) most of the encoding's work; key order does not reach inside a list of
floats, so that text is the same in both. :func:`dumps_shared` gives exactly what the given C
encoder's ``encode`` gives, with each such list's text taken from a small memo of the lists
encoded last (by identity, and used only while the list holds the very float objects it held).
"""

from __future__ import annotations

import json
import operator
import re
from itertools import chain, count

#: Lists shorter than this are left to the encoder (the memo would cost more than their text).
MIN_SHARED = 8
#: Memo entries kept: a pass has a few fits of three lists each.
MEMO_SIZE = 64
#: Nesting walked to find the lists (deeper values are left to the encoder as they are).
MAX_DEPTH = 16

_LIST = json.JSONEncoder(allow_nan=False, separators=(",", ":"))
_MEMO: dict = {}
_LIST_TYPE, _FLOAT_TYPE = {list}, {float}
_CONTAINERS = (dict, list)
#: A token as the encoder writes it (ASCII escapes of NUL), its number captured.
_TOKEN_TEXT = re.compile(r'"\\u0000jsonshare (\d+)\\u0000"')
_TOKENS = count()


def dumps_shared(value, encoder: json.JSONEncoder) -> str:
    """``encoder.encode(value)``, the same text; ``encoder`` compact (``separators=(",", ":")``, no
    indent) with ``allow_nan=False``, any other goes straight to ``encoder.encode``."""
    if encoder.item_separator != "," or encoder.key_separator != ":" or encoder.allow_nan \
            or encoder.indent is not None:
        return encoder.encode(value)
    lists: dict = {}
    shallow = _replace(value, lists, 0)
    if not lists:
        return encoder.encode(value)
    try:
        parts = _TOKEN_TEXT.split(encoder.encode(shallow))
        found = parts[1::2]
        if len(found) != len(lists) or set(found) != lists.keys():
            return encoder.encode(value)     # a string of the data spelled like a token
        parts[1::2] = [_list_text(lists[token]) for token in found]
    except (TypeError, ValueError, RecursionError):
        return encoder.encode(value)         # its own error, the first in its order
    return "".join(parts)


def _replace(value, lists: dict, depth: int):
    """``value`` with every long list of floats replaced by a fresh token string (``lists``:
    the token's number -> the list); the dicts and lists on the way copied, nothing else."""
    kind = type(value)
    if depth > MAX_DEPTH or (kind is not dict and kind is not list):
        return value
    depth += 1
    if kind is dict:         # (scalars without a call: most of a summary's values)
        return {k: _replace(v, lists, depth) if type(v) in _CONTAINERS else v for k, v in value.items()}
    if _float_rows(value):
        token = str(next(_TOKENS))
        lists[token] = value
        return "\x00jsonshare " + token + "\x00"
    return [_replace(v, lists, depth) if type(v) in _CONTAINERS else v for v in value]


def _float_rows(values: list) -> bool:
    """A list of at least :data:`MIN_SHARED` floats, or of such lists (a matrix)."""
    if not values:
        return False
    if type(values[0]) is list:
        return set(map(type, values)) == _LIST_TYPE and min(map(len, values)) >= MIN_SHARED \
            and set(map(type, chain.from_iterable(values))) == _FLOAT_TYPE
    return len(values) >= MIN_SHARED and set(map(type, values)) == _FLOAT_TYPE


def _snapshot(values: list) -> tuple:
    if type(values[0]) is list:
        return tuple((row, tuple(row)) for row in values)
    return tuple(values)


def _unchanged(values: list, snapshot: tuple) -> bool:
    """The same float objects in the same places as when the text was made (floats are immutable)."""
    if len(values) != len(snapshot):
        return False
    if type(values[0]) is list:
        return all(row is kept and len(row) == len(items) and all(map(operator.is_, row, items))
                   for row, (kept, items) in zip(values, snapshot))
    return all(map(operator.is_, values, snapshot))


def _list_text(values: list) -> str:
    entry = _MEMO.get(id(values))
    if entry is not None and entry[0] is values and _unchanged(values, entry[1]):
        return entry[2]
    text = _LIST.encode(values)              # raises for a non-finite float, as the encoder would
    if len(_MEMO) >= MEMO_SIZE:
        _MEMO.clear()
    _MEMO[id(values)] = (values, _snapshot(values), text)
    return text

"""typer's parameter coercion without pydantic for the values whose conversion is unambiguous
(issue 19): :class:`LightCoercion`, installed on typer's parameter class by :func:`install`."""

from __future__ import annotations

import enum
import re
import sys
import types
import typing


class LightCoercion:
    """Typer's runtime coercion of one parameter, without pydantic where the conversion is plain.

    Typer (0.2x) builds a pydantic TypeAdapter for every parameter it processes, including an
    option left at its default; importing pydantic for that is ~60 % of ``trackproc COMMAND
    --help`` and ~50 ms of every command (issue 19). Values whose conversion is unambiguous pass
    here with exactly the result typer's adapter gives (:func:`plain_value`): None, a value
    already of the annotated type, a string for a ``str`` option, an enum member's exact value,
    a plain decimal number for a number option (within its min/max if it has them). Anything
    else (a bad value, a number out of its range, clamping, a custom parser, ...) goes to
    typer's own coercion, built on first use, so validation and messages stay typer's.
    """

    __slots__ = ("_param", "_build", "_full")

    def __init__(self, param, build):
        self._param, self._build, self._full = param, build, None

    def coerce(self, value, param, ctx):
        if value is None:
            return () if (param.multiple or param.nargs == -1) else None
        if plain_default(self._param, value, ctx):
            return value
        plain = plain_value(self._param.type_descriptor, value)
        if plain is not NOT_PLAIN:
            return plain
        if self._full is None:
            self._full = self._build(self._param)
        return self._full.coerce(value, param=param, ctx=ctx)


def plain_default(param, value, ctx) -> bool:
    """True for the command's own default (not a config file's) already of the annotated type:
    valid by construction, nothing to convert or check."""
    source = getattr(ctx, "get_parameter_source", lambda name: None)(param.name)
    return (getattr(source, "name", None) == "DEFAULT"
            and type(value) is param.type_descriptor.annotation)


NOT_PLAIN = object()
#: Spellings whose value every parser agrees on (no "nan", "1_000", hex, surrounding blanks).
_DECIMAL = re.compile(r"[+-]?(?:\d+\.?\d*|\.\d+)(?:[eE][+-]?\d{1,3})?")
_INTEGER = re.compile(r"[+-]?\d{1,18}")


def plain_value(descriptor, value):
    """``value`` converted as typer's adapter would, or ``NOT_PLAIN`` when that needs typer."""
    info = descriptor.parameter_info
    if getattr(info, "parser", None) is not None or getattr(info, "click_type", None) is not None:
        return NOT_PLAIN
    ann = descriptor.annotation
    if typing.get_origin(ann) in (typing.Union, types.UnionType):      # Optional[X]
        args = [a for a in typing.get_args(ann) if a is not type(None)]
        if len(args) != 1:
            return NOT_PLAIN
        ann = args[0]
    if typing.get_origin(ann) is list and isinstance(value, (list, tuple)):
        args = typing.get_args(ann)
        if len(args) != 1:
            return NOT_PLAIN
        items = [_plain_leaf(args[0], info, item) for item in value]
        return NOT_PLAIN if any(item is NOT_PLAIN for item in items) else items
    return _plain_leaf(ann, info, value)


def _plain_leaf(ann, info, value):
    if ann is bool:
        return value if isinstance(value, bool) else NOT_PLAIN
    if ann is str:
        return value if isinstance(value, str) else NOT_PLAIN
    if isinstance(ann, type) and issubclass(ann, enum.Enum):
        if isinstance(value, ann):
            return value
        if isinstance(value, str):
            try:
                return ann(value)            # an exact member value: the member typer would give
            except ValueError:
                return NOT_PLAIN
        return NOT_PLAIN
    if ann in (int, float):
        if getattr(info, "clamp", False):
            return NOT_PLAIN                # clamping: typer's adapter does it
        if type(value) is ann:
            number = value
        elif not isinstance(value, str):
            return NOT_PLAIN
        elif ann is int:
            if not _INTEGER.fullmatch(value):
                return NOT_PLAIN
            number = int(value)
        elif _DECIMAL.fullmatch(value):
            number = float(value)
            if not number - number == 0.0:      # not finite ("1e999"): typer's message
                return NOT_PLAIN
        else:
            return NOT_PLAIN
        lo, hi = getattr(info, "min", None), getattr(info, "max", None)
        if (lo is not None and not number >= lo) or (hi is not None and not number <= hi):
            return NOT_PLAIN                # out of range: typer's adapter says so, in its words
        return number
    return NOT_PLAIN


def install() -> None:
    """Install :class:`LightCoercion` on typer's parameter class (once; a typer without this
    hook keeps its own behaviour)."""
    core = sys.modules.get("typer.core")
    cls = getattr(core, "_TyperParameter", None)
    builder = getattr(core, "build_runtime_param", None)
    if (cls is None or builder is None or not hasattr(cls, "get_runtime_param")
            or getattr(cls.get_runtime_param, "_trackproc_light", False)):
        return

    def build(param):
        return builder(param.type_descriptor)

    def get_runtime_param(self):
        if getattr(self, "_runtime_param", None) is None:
            self._runtime_param = LightCoercion(self, build)
        return self._runtime_param

    get_runtime_param._trackproc_light = True
    cls.get_runtime_param = get_runtime_param

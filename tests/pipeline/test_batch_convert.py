"""``trackproc batch`` settings converted from TOML values, environment text and flags
(pipeline/batch/config.convert): each kind's accepted spellings and its one-line error naming the
key, flag or variable. Expected values written by hand from the settings' documented forms."""

from __future__ import annotations

import os

import pytest

from trackproc.errors import InputError
from trackproc.pipeline.batch.config import convert
from trackproc.pipeline.batch.schema import Opt


def _opt(kind, default=None, choices=(), check=None):
    return Opt("s", "k", kind, default, ("--k",), "help", choices=choices, check=check)


@pytest.mark.parametrize("kind, value, origin, expected", [
    ("str", "abc", "config", "abc"),
    ("str", "", "flag", None),
    ("choice", " fast ", "env", "fast"),
    ("choice", "none", "config", None),
    ("path", "", "config", None),
    ("list", "a, b,,c", "env", ("a", "b", "c")),
    ("list", "a, b", "config", ("a, b",)),
    ("list", ["a,b", "c"], "flag", ("a", "b", "c")),
    ("list", ["a,b", "c"], "config", ("a,b", "c")),
    ("bool", "Yes", "env", True),
    ("bool", "off", "flag", False),
    ("bool", True, "config", True),
    ("int", " 7 ", "env", 7),
    ("int", 7, "config", 7),
    ("float", "2.5", "flag", 2.5),
    ("float", 3, "config", 3.0),
    ("duration", "2m", "env", 120.0),
    ("duration", 90, "config", 90.0),
    ("degree", "AUTO", "config", "auto"),
    ("degree", "4", "env", 4),
    ("map", "a=1, b=2.5", "flag", {"a": 1.0, "b": 2.5}),
    ("map", {"a": 3}, "config", {"a": 3.0}),
    ("map", ["a=1", "b=2"], "config", {"a": 1.0, "b": 2.0}),
    ("str", None, "config", None),
])
def test_each_kind_converts_its_spellings(kind, value, origin, expected):
    got = convert(_opt(kind, choices=("fast", "slow")), value, origin, "c.toml", "/base")
    assert got == expected and type(got) is type(expected)


def test_paths_are_joined_to_the_base_directory():
    assert convert(_opt("path"), "x/y.csv", "config", "c.toml", "/base") == os.path.normpath("/base/x/y.csv")
    assert convert(_opt("paths"), "a,/abs/b", "env", None, "/base") == (os.path.normpath("/base/a"), "/abs/b")


@pytest.mark.parametrize("kind, value, origin, found, expected", [
    ("str", 3, "config", "3", "a string"),                 # text is quoted, other values are not
    ("choice", "medium", "flag", "'medium'", "fast or slow"),
    ("list", "a, b", "config", None, None),
    ("bool", "yes", "config", "'yes'", "true or false"),
    ("int", True, "config", "True", "an integer"),
    ("int", "7.5", "env", "'7.5'", "an integer"),
    ("float", "inf", "flag", "'inf'", "a number"),
    ("duration", "soon", "env", "'soon'", "seconds, or a number with s, m, h or d (90s, 6h, 1d)"),
    ("degree", -1, "config", "-1", "an integer >= 0 or auto"),
    ("degree", "4", "config", "'4'", "an integer >= 0 or auto"),
    ("map", "a", "flag", "'a'", "NAME=VALUE pairs with numeric values"),
    ("map", "a=x", "flag", "'a=x'", "NAME=VALUE pairs with numeric values"),
    ("map", "a=0", "env", "'a=0.0'", "NAME=SIGMA with SIGMA > 0"),
])
def test_a_bad_value_is_one_line_naming_where_it_came_from(kind, value, origin, found, expected):
    opt = _opt(kind, choices=("fast", "slow"))
    if found is None:                                     # a TOML string where a list is due is accepted
        assert convert(opt, value, origin, "c.toml") == ("a, b",)
        return
    with pytest.raises(InputError) as info:
        convert(opt, value, origin, "c.toml")
    where = {"config": "c.toml, column 's.k'", "flag": "option '--k'", "env": f"column '{opt.env}'"}[origin]
    assert str(info.value) == f"{where}: invalid setting; found {found}; expected {expected}"

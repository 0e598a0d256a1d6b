"""Resolution of the settings of ``trackproc batch``: flag > environment variable > config file > default.

The settings themselves (keys, flags, variables, defaults, checks) are the table
:data:`trackproc.pipeline.batch.schema.SCHEMA`. Only the standard library is imported here:
the CLI imports this module at start-up.
"""

from __future__ import annotations

import difflib
import math
import os
from dataclasses import dataclass, field
from typing import Any, Mapping, Optional

from trackproc.errors import InputError
from trackproc.pipeline.batch.schema import BY_NAME, CONFIG_ENV, ENV_PREFIX, SCHEMA, SECTIONS, Opt


@dataclass
class Settings:
    """Resolved settings: ``values[section][key]`` and where each came from
    (``origins["section.key"]`` in flag | env | config | default)."""

    values: dict
    origins: dict
    config_file: Optional[str] = None
    unknown_env: list = field(default_factory=list)

    def __getitem__(self, section: str) -> dict:
        return self.values[section]

    def get(self, name: str):
        section, key = name.split(".")
        return self.values[section][key]

    def section(self, section: str) -> dict:
        """A copy of one section's values (JSON-ready: lists, not tuples); {} for a section
        without settings."""
        return {k: (list(v) if isinstance(v, tuple) else v) for k, v in self.values.get(section, {}).items()}


# ----------------------------------------------------------------------------- parsing

_TRUE = {"1", "true", "yes", "on"}
_FALSE = {"0", "false", "no", "off"}


def _where(opt: Opt, origin: str, config_file: Optional[str]) -> dict:
    if origin == "flag":
        return {"column": opt.flag}
    if origin == "env":
        return {"column": opt.env}
    return {"file": config_file, "column": opt.name}


def _expected(opt: Opt) -> str:
    return {
        "str": "a string", "path": "a path", "paths": "a list of directories or globs",
        "list": "a list of strings", "int": "an integer", "float": "a number", "bool": "true or false",
        "duration": "seconds, or a number with s, m, h or d (90s, 6h, 1d)",
        "choice": " or ".join(opt.choices), "degree": "an integer >= 0 or auto",
        "map": "NAME=VALUE pairs with numeric values",
    }[opt.kind]


def _split(text: str) -> list:
    return [part.strip() for part in text.split(",") if part.strip()]


def _as_text(opt: Opt, value, text: bool, base_dir, bad):
    """``str``, ``path`` and ``choice``: empty (or ``none`` for a choice without default) is unset."""
    kind = opt.kind
    if not isinstance(value, str):
        raise bad()
    value = value.strip() if kind == "choice" else value
    if kind == "choice":
        if value in ("", "none") and opt.default is None:
            return None
        if value not in opt.choices:
            raise bad()
    if kind == "str" and value == "":
        return None
    if kind == "path":
        if value == "":
            return None
        return _path(value, base_dir)
    return value


def _as_list(opt: Opt, value, text: bool, base_dir, bad):
    """``list`` and ``paths``: comma-separated text, or a TOML list of strings."""
    if isinstance(value, str) and text:
        items = _split(value)
    elif isinstance(value, str):
        items = [value]
    elif isinstance(value, (list, tuple)):
        items = []
        for item in value:
            if not isinstance(item, str):
                raise bad()
            items.extend(_split(item) if text else [item])
    else:
        raise bad()
    if opt.kind == "paths":
        items = [_path(item, base_dir) for item in items]
    return tuple(items)


def _as_bool(opt: Opt, value, text: bool, base_dir, bad):
    if isinstance(value, bool):
        return value
    if isinstance(value, str) and text and value.strip().lower() in _TRUE | _FALSE:
        return value.strip().lower() in _TRUE
    raise bad()


def _as_int(opt: Opt, value, text: bool, base_dir, bad):
    if isinstance(value, bool):
        raise bad()
    if isinstance(value, str) and text:
        try:
            value = int(value.strip())
        except ValueError:
            raise bad() from None
    if not isinstance(value, int):
        raise bad()
    return _checked(opt, value, bad)


def _as_duration(opt: Opt, value, text: bool, base_dir, bad):
    """Seconds, or text with a unit (``parse_duration``)."""
    from trackproc.types.checks import parse_duration  # start-up: numpy and pandas; this module is stdlib-only

    if isinstance(value, bool) or not isinstance(value, (int, float, str)):
        raise bad()
    try:
        return _checked(opt, parse_duration(value, opt.name), bad)
    except InputError:
        raise bad() from None


def _as_float(opt: Opt, value, text: bool, base_dir, bad):
    if isinstance(value, bool):
        raise bad()
    if isinstance(value, str) and text:
        try:
            value = float(value.strip())
        except ValueError:
            raise bad() from None
    if not isinstance(value, (int, float)) or not math.isfinite(value):
        raise bad()
    return _checked(opt, float(value), bad)


def _as_degree(opt: Opt, value, text: bool, base_dir, bad):
    """A non-negative integer or ``auto``."""
    if isinstance(value, str):
        if value.strip().lower() == "auto":
            return "auto"
        if not text:
            raise bad()
        try:
            value = int(value.strip())
        except ValueError:
            raise bad() from None
    if isinstance(value, bool) or not isinstance(value, int) or value < 0:
        raise bad()
    return value


def _as_map(opt: Opt, value, text: bool, base_dir, bad):
    """NAME=SIGMA pairs (text or a TOML list of them, or a TOML table), each SIGMA > 0."""
    if isinstance(value, Mapping):
        pairs = list(value.items())
    elif isinstance(value, (str, list, tuple)) and (text or not isinstance(value, str)):
        items = _split(value) if isinstance(value, str) else [p for v in value for p in _split(str(v))]
        pairs = []
        for item in items:
            name, sep, number = item.partition("=")
            if not sep or not name.strip():
                raise bad(found=item)
            pairs.append((name.strip(), number.strip()))
    else:
        raise bad()
    out = {}
    for name, number in pairs:
        try:
            number = float(number) if not isinstance(number, bool) else math.nan
        except (TypeError, ValueError):
            raise bad(found=f"{name}={number}") from None
        if not (math.isfinite(number) and number > 0):
            raise bad(found=f"{name}={number}", expected="NAME=SIGMA with SIGMA > 0")
        out[str(name)] = number
    return out


#: The converter of each option kind of the schema.
_CONVERTERS = {"str": _as_text, "path": _as_text, "choice": _as_text, "list": _as_list, "paths": _as_list,
               "bool": _as_bool, "int": _as_int, "duration": _as_duration, "float": _as_float,
               "degree": _as_degree, "map": _as_map}


def convert(opt: Opt, value, origin: str, config_file: Optional[str] = None, base_dir: Optional[str] = None):
    """``value`` (TOML value, environment text or flag value) as the type of ``opt``.

    Text (environment, flags) is parsed; TOML values must already have the right type.
    Relative paths are joined to ``base_dir`` (the config file's directory for config values).
    Raises :class:`InputError` (exit 2) naming the key, flag or variable.
    """
    def bad(found=value, expected=None):
        return InputError("invalid setting", found=found, expected=expected or _expected(opt),
                          **_where(opt, origin, config_file))

    if value is None:
        return None
    converter = _CONVERTERS.get(opt.kind)
    if converter is None:  # pragma: no cover - every kind of the schema has one
        raise AssertionError(opt.kind)
    return converter(opt, value, origin in ("env", "flag"), base_dir, bad)


def _checked(opt: Opt, value, bad):
    if opt.check is not None:
        ok, expected = opt.check
        if not ok(value):
            raise bad(expected=expected)
    return value


def _path(value: str, base_dir: Optional[str]) -> str:
    value = os.path.expanduser(value)
    if base_dir and not os.path.isabs(value):
        return os.path.normpath(os.path.join(base_dir, value))
    return value


def load_toml(path: str) -> dict:
    """The TOML document of ``path`` (stdlib tomllib; tomli on Python 3.10)."""
    try:
        import tomllib  # Python >= 3.11
    except ImportError:  # Python 3.10
        try:
            import tomli as tomllib  # type: ignore[no-redef]
        except ImportError:
            raise InputError("a TOML config file needs Python >= 3.11 (tomllib) or the tomli package",
                             file=path, expected="pip install tomli, or give every setting as a flag") from None
    try:
        with open(path, "rb") as handle:
            return tomllib.load(handle)
    except FileNotFoundError:
        raise InputError("config file not found", file=path) from None
    except IsADirectoryError:
        raise InputError("is a directory, expected a TOML config file", file=path) from None
    except PermissionError:
        raise InputError("permission denied", file=path) from None
    except UnicodeDecodeError as exc:
        raise InputError("not UTF-8 text", file=path, found=str(exc)) from None
    except tomllib.TOMLDecodeError as exc:
        raise InputError(f"invalid TOML: {exc}", file=path) from None


def _closest(name: str, candidates) -> str:
    match = difflib.get_close_matches(name, list(candidates), n=1)
    return f" (did you mean {match[0]}?)" if match else ""


def resolve(config_file: Optional[str] = None, flags: Optional[Mapping[str, Any]] = None,
            environ: Optional[Mapping[str, str]] = None) -> Settings:
    """Resolve every setting: flag > environment > config file > default.

    ``flags``: ``"section.key"`` -> value as parsed by the CLI (None = not given);
    ``environ``: the environment (default ``os.environ``); ``config_file``: TOML path, or None
    (then ``TRACKPROC_BATCH_CONFIG`` if set). Unknown sections, keys and ``TRACKPROC_BATCH_*``
    variables are errors (exit 2): a typo must not silently fall back to a default.
    """
    environ = os.environ if environ is None else environ
    flags = dict(flags or {})
    if config_file is None and environ.get(CONFIG_ENV):
        config_file = environ[CONFIG_ENV]
    document: dict = {}
    base_dir = None
    if config_file is not None:
        document = load_toml(config_file)
        base_dir = os.path.dirname(config_file) or "."
        for section, body in document.items():
            if section not in SECTIONS:
                raise InputError("unknown section", file=config_file, column=f"[{section}]",
                                 expected="sections " + ", ".join(f"[{s}]" for s in SECTIONS)
                                 + _closest(section, SECTIONS))
            if not isinstance(body, dict):
                raise InputError("expected a section", file=config_file, column=section, found=body,
                                 expected=f"[{section}] with key = value lines")
            for key in body:
                if f"{section}.{key}" not in BY_NAME:
                    keys = [o.key for o in SCHEMA if o.section == section]
                    raise InputError("unknown setting", file=config_file, column=f"{section}.{key}",
                                     expected="one of " + ", ".join(keys) + _closest(key, keys))
    known_env = {o.env for o in SCHEMA} | {CONFIG_ENV}
    unknown_env = sorted(k for k in environ if k.startswith(ENV_PREFIX) and k not in known_env)
    if unknown_env:
        names = sorted(known_env)
        raise InputError("unknown environment variable", column=unknown_env[0],
                         expected="one of the documented TRACKPROC_BATCH_* variables" + _closest(unknown_env[0], names))
    values: dict = {s: {} for s in SECTIONS}
    origins: dict = {}
    for opt in SCHEMA:
        flag_value = flags.get(opt.name)
        if isinstance(flag_value, (list, tuple)) and not flag_value:
            flag_value = None
        if flag_value is not None:
            value, origin = convert(opt, flag_value, "flag"), "flag"
        elif environ.get(opt.env, "") != "":
            value, origin = convert(opt, environ[opt.env], "env"), "env"
        elif opt.key in document.get(opt.section, {}):
            value, origin = convert(opt, document[opt.section][opt.key], "config", config_file, base_dir), "config"
        else:
            value, origin = opt.default, "default"
        values[opt.section][opt.key] = value
        origins[opt.name] = origin
    return Settings(values=values, origins=origins, config_file=config_file)

"""One configuration file for the defaults every command honours (issue 16).

``$TRACKPROC_CONFIG``, else ``$XDG_CONFIG_HOME/trackproc/config.toml`` (``~/.config/...``), when it
exists::

    [defaults]                     # every command that has the option
    eop = "finals2000A.all"        # relative paths: to the config file's directory
    stations = "stations.csv"
    carrier_hz = 2.2e9

    [refine]                       # one command's own defaults, over [defaults]
    doppler_bias = "offset+drift"

Keys are option names with ``_`` for ``-`` (``carrier_hz`` for ``--carrier-hz``). A few defaults
also come from the environment (:data:`ENV_KEYS`, e.g. ``TRACKPROC_EOP``). Precedence, as in
``batch``: flag > environment > config file > built-in default; click applies it: the file and the
environment fill the context's ``default_map``, which a flag overrides. An unknown section or key
is an input error naming the nearest valid one: a typo never falls back silently to a default.
``batch`` keeps its own TOML (docs/batch.md) and is not configured here.
"""

from __future__ import annotations

import difflib
import os
from pathlib import Path

from trackproc.errors import InputError

CONFIG_ENV = "TRACKPROC_CONFIG"
#: Defaults that the environment may give, as ``TRACKPROC_<KEY>`` (upper case).
ENV_KEYS = ("eop", "dut1", "stations", "carrier_hz", "mode", "force", "earth", "range_rate_model")
#: Commands configured elsewhere.
SKIP = ("batch",)


def config_path() -> Path | None:
    """The config file in force, or None. A ``TRACKPROC_CONFIG`` that names no file is an error."""
    named = os.environ.get(CONFIG_ENV)
    if named:
        path = Path(named)
        if not path.is_file():
            raise InputError("config file not found", file=named, column=CONFIG_ENV,
                             expected="a TOML file of trackproc defaults")
        return path
    base = Path(os.environ.get("XDG_CONFIG_HOME") or Path.home() / ".config")
    path = base / "trackproc" / "config.toml"
    return path if path.is_file() else None


def _load_toml(path: Path) -> dict:
    try:
        import tomllib
    except ImportError:  # Python 3.10
        import tomli as tomllib
    try:
        return tomllib.loads(path.read_text(encoding="utf-8"))
    except (OSError, UnicodeDecodeError) as exc:
        raise InputError(f"config file unreadable ({exc.__class__.__name__})", file=str(path)) from None
    except tomllib.TOMLDecodeError as exc:
        raise InputError(f"not valid TOML: {exc}", file=str(path), expected="a TOML file of trackproc defaults") from None


def _nearest(word: str, choices) -> str:
    close = difflib.get_close_matches(word, sorted(choices), n=1)
    return f"one of {', '.join(sorted(choices))}" + (f" (did you mean {close[0]!r}?)" if close else "")


def _option_names(command) -> dict[str, str]:
    """Config key (the long flag without ``--``, ``_`` for ``-``) -> click parameter name."""
    out = {}
    for p in getattr(command, "params", []):
        if getattr(p, "param_type_name", "") != "option" or p.name == "help":
            continue
        longs = [o for o in p.opts if o.startswith("--")]
        out[(longs[0][2:] if longs else p.name).replace("-", "_")] = p.name
    return out


def _resolve_path(value, base: Path):
    """A relative path in the config file is relative to the file's directory (when it exists there)."""
    if isinstance(value, str) and value and not os.path.isabs(value) and (base / value).exists():
        return str(base / value)
    return value


def _annotation(param):
    """The Python type an option takes (``Optional[X]`` -> X), or None when unknown."""
    import typing

    ann = getattr(getattr(param, "type_descriptor", None), "annotation", None)
    args = [a for a in typing.get_args(ann) if a is not type(None)] if typing.get_origin(ann) is typing.Union else None
    return args[0] if args and len(args) == 1 else ann


def _check_type(command, param_name: str, value, path: Path, section: str, key: str) -> None:
    """A config value the option cannot take (a word for a number, a list for a path, a name
    outside the choices) is an input error naming the file and the key."""
    import enum
    import math

    param = next((p for p in getattr(command, "params", []) if p.name == param_name), None)
    ann = _annotation(param) if param is not None else None
    if ann is None:
        return
    problem = None
    if isinstance(ann, type) and issubclass(ann, enum.Enum):
        choices = [str(m.value) for m in ann]
        if str(value) not in choices or isinstance(value, (dict, list, bool)):
            problem = "one of " + ", ".join(choices)
    elif ann is bool:
        if not isinstance(value, bool):
            problem = "true or false"
    elif ann in (int, float):
        number = None
        if not isinstance(value, (bool, dict, list)):
            try:
                number = ann(value)
            except (TypeError, ValueError, OverflowError):
                number = None
        if number is None or (ann is float and not math.isfinite(number)):
            problem = "an integer" if ann is int else "a finite number"
    elif ann is str and isinstance(value, (dict, list)):
        problem = "a string"
    if problem:
        raise InputError("wrong type of value", file=str(path), column=f"[{section}] {key}", found=value,
                         expected=f"{problem} (as --{param_name.replace('_', '-')} takes)")


def default_map(root) -> dict:
    """The click ``default_map`` of the root command ``root``: per command, its defaults from the
    environment and the config file (empty when neither gives any)."""
    commands = {name: cmd for name, cmd in getattr(root, "commands", {}).items() if name not in SKIP}
    options = {name: _option_names(cmd) for name, cmd in commands.items()}
    every = set().union(*(set(o) for o in options.values())) if options else set()
    out: dict = {name: {} for name in commands}
    path = config_path()
    if path is not None:
        doc = _load_toml(path)
        for section, table in doc.items():
            if section != "defaults" and section not in commands:
                raise InputError("unknown section", file=str(path), column=f"[{section}]", found=section,
                                 expected="[defaults] or a command: " + _nearest(section, list(commands) + ["defaults"]))
            if not isinstance(table, dict):
                raise InputError("not a table", file=str(path), column=section, found=table,
                                 expected=f"[{section}] with key = value lines")
            valid = every if section == "defaults" else options[section]
            for key in table:
                if key.replace("-", "_") not in valid:
                    raise InputError("unknown key", file=str(path), column=f"[{section}] {key}", found=key,
                                     expected=_nearest(key.replace("-", "_"), valid))
        defaults = doc.get("defaults", {})
        for name in commands:
            merged = {k.replace("-", "_"): (v, "defaults", k) for k, v in defaults.items()}
            merged.update({k.replace("-", "_"): (v, name, k) for k, v in doc.get(name, {}).items()})
            for key, (value, section, written) in merged.items():
                if key in options[name]:
                    _check_type(commands[name], options[name][key], value, path, section, written)
                    out[name][options[name][key]] = _resolve_path(value, path.parent)
    for key in ENV_KEYS:
        value = os.environ.get(f"TRACKPROC_{key.upper()}")
        if value:
            for name in commands:
                if key in options[name]:
                    out[name][options[name][key]] = value
    return {name: values for name, values in out.items() if values}

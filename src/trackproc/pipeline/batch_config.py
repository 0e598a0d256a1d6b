"""Settings of ``trackproc batch``: one schema for the TOML file, the flags and the environment.

Every setting is a key of a TOML section (``[batch]``, ``[ingest]``, ``[smooth]``,
``[refine]``, ``[estimate]``), a command-line flag and an environment variable, resolved in this order:

    flag  >  environment variable  >  config file  >  default

Environment variables are named ``TRACKPROC_BATCH_<KEY>`` for the ``[batch]`` section and
``TRACKPROC_BATCH_<SECTION>_<KEY>`` for the others (``TRACKPROC_BATCH_WORKERS``,
``TRACKPROC_BATCH_SMOOTH_DEGREE``); ``TRACKPROC_BATCH_CONFIG`` names the config file when the
command line gives none. Lists in the environment (and in a flag given once) are comma
separated (``TRACKPROC_BATCH_INPUTS=in/a,in/b``), maps are ``NAME=VALUE`` pairs
(``x=1000,vx=1``), booleans are ``1/0``, ``true/false``, ``yes/no`` or ``on/off``.

Relative paths in the config file are relative to the config file's directory; relative paths
in flags and environment variables are relative to the working directory.

Step options (``affects=True``) are part of each result's content hash; run options
(workers, scheduler, log, lock) are not, so changing them never redoes any work.

Only the standard library is imported here: the CLI imports this module at start-up.
"""

from __future__ import annotations

import math
import os
from dataclasses import dataclass, field
from typing import Any, Mapping, Optional

from trackproc.errors import InputError

#: Sections in the order they are documented; ``batch`` holds the run options.
SECTIONS = ("batch", "ingest", "smooth", "refine", "estimate")
ENV_PREFIX = "TRACKPROC_BATCH_"
CONFIG_ENV = "TRACKPROC_BATCH_CONFIG"

#: File suffixes taken from an input directory (a glob takes whatever it matches).
DEFAULT_PATTERNS = ("*.csv", "*.parquet", "*.pq", "*.arrow", "*.arrows", "*.feather", "*.ipc",
                    "*.tdm", "*.kvn", "*.aer")


def _positive(value) -> bool:
    return math.isfinite(value) and value > 0


def _non_negative(value) -> bool:
    return math.isfinite(value) and value >= 0


@dataclass(frozen=True)
class Opt:
    """One setting: TOML ``section.key``, its flag, its environment variable, type and default.

    ``kind``: str | path | paths (list of paths or globs) | list (of str) | int | float | bool |
    choice | degree (``auto`` or an int >= 0) | map (name -> float). ``affects``: part of the
    content hash of the results (step options). ``check``: (predicate, expected text).
    """

    section: str
    key: str
    kind: str
    default: Any
    flags: tuple
    help: str
    choices: tuple = ()
    affects: bool = False
    check: Optional[tuple] = None
    metavar: Optional[str] = None

    @property
    def name(self) -> str:
        return f"{self.section}.{self.key}"

    @property
    def env(self) -> str:
        middle = "" if self.section == "batch" else f"{self.section.upper()}_"
        return f"{ENV_PREFIX}{middle}{self.key.upper()}"

    @property
    def dest(self) -> str:
        """Python identifier of the flag's parameter."""
        return f"{self.section}__{self.key}"

    @property
    def flag(self) -> str:
        return self.flags[0].split("/")[0]


_POS = (_positive, "a number > 0")
_NONNEG = (_non_negative, "a number >= 0")
_INT_NONNEG = (lambda v: v >= 0, "an integer >= 0")
_INT_POS = (lambda v: v >= 1, "an integer >= 1")

SCHEMA: tuple[Opt, ...] = (
    # ------------------------------------------------------------------ [batch]: the run
    Opt("batch", "inputs", "paths", (), ("--input", "-i"),
        "Input directory (its files with a known suffix) or glob (quote it; ** recurses); repeatable.",
        metavar="DIR|GLOB"),
    Opt("batch", "output", "path", None, ("--output", "-o"),
        "Output directory: passes/, estimates/, summary.json, summary.csv, the lock file.", metavar="DIR"),
    Opt("batch", "steps", "list", ("ingest", "smooth"), ("--steps",),
        "The chain, comma separated, in order: ingest, smooth, refine, estimate.",
        metavar="STEP[,STEP]"),
    Opt("batch", "patterns", "list", DEFAULT_PATTERNS, ("--patterns",),
        "File patterns taken from an input directory (not from a glob).", metavar="GLOB[,GLOB]"),
    Opt("batch", "workers", "int", 0, ("--workers", "-j"),
        "Worker processes (0: one per core; 1: in this process).", check=_INT_NONNEG, metavar="N"),
    Opt("batch", "scheduler", "str", None, ("--scheduler",),
        "Run on an existing Dask distributed cluster (needs the optional dask extra of trackproc).", metavar="tcp://HOST:PORT"),
    Opt("batch", "force", "bool", False, ("--force/--no-force",),
        "Redo every result, up to date or not."),
    Opt("batch", "retry_failed", "bool", False, ("--retry-failed/--no-retry-failed",),
        "Retry inputs whose recorded failure is up to date (data errors are otherwise not retried)."),
    Opt("batch", "wait", "bool", False, ("--wait/--no-wait",),
        "When another run holds the output directory's lock, wait for it instead of exiting."),
    Opt("batch", "wait_timeout_s", "float", 0.0, ("--wait-timeout",),
        "Give up waiting for the lock after S seconds (0: wait as long as it takes).", check=_NONNEG,
        metavar="S"),
    Opt("batch", "log", "path", None, ("--log",),
        "Append the log to FILE instead of stderr.", metavar="FILE"),
    # ------------------------------------------------------------------ [ingest]
    Opt("ingest", "stations", "path", None, ("--stations",),
        "Stations table: station, lat_deg, lon_deg, height_m [, range_bias_m].", affects=True,
        metavar="STATIONS.csv"),
    Opt("ingest", "carrier_hz", "float", None, ("--carrier-hz",),
        "Nominal carrier frequency, Hz (Doppler inputs).", affects=True, check=_POS, metavar="F"),
    Opt("ingest", "mode", "choice", None, ("--mode",), "Doppler link: one-way or two-way.",
        choices=("one-way", "two-way"), affects=True),
    Opt("ingest", "max_gap_s", "float", 300.0, ("--max-gap",),
        "Start a new pass after a gap longer than S seconds.", affects=True, check=_POS, metavar="S"),
    Opt("ingest", "layout", "choice", "auto", ("--layout",), "Input layout (auto: detected).",
        choices=("auto", "wide", "long", "doptrack", "aer", "tdm"), affects=True),
    Opt("ingest", "drop_invalid", "bool", False, ("--drop-invalid/--no-drop-invalid",),
        "Drop invalid samples (counted in the summary) instead of failing the input.", affects=True),
    Opt("ingest", "tdm_two_way_range", "choice", "one-way-equivalent", ("--tdm-two-way-range",),
        "How a CCSDS TDM writes two-way RANGE.", choices=("one-way-equivalent", "round-trip"), affects=True),
    Opt("ingest", "sigma_range_m", "float", 10.0, ("--sigma-range-m",), "Default range sigma, m.",
        affects=True, check=_POS),
    Opt("ingest", "sigma_range_rate_m_s", "float", 0.1, ("--sigma-range-rate-m-s",),
        "Default range-rate sigma, m/s.", affects=True, check=_POS),
    Opt("ingest", "sigma_doppler_hz", "float", 1.0, ("--sigma-doppler-hz",), "Default Doppler sigma, Hz.",
        affects=True, check=_POS),
    Opt("ingest", "sigma_angle_deg", "float", 0.01, ("--sigma-angle-deg",),
        "Default azimuth/elevation sigma, deg.", affects=True, check=_POS),
    # ------------------------------------------------------------------ [smooth]
    Opt("smooth", "degree", "degree", "auto", ("--degree",),
        "Polynomial degree, or auto (minimum BIC up to --max-degree).", affects=True, metavar="N|auto"),
    Opt("smooth", "max_degree", "int", 30, ("--max-degree",), "Largest degree auto tries.", affects=True,
        check=_INT_NONNEG, metavar="N"),
    Opt("smooth", "basis", "choice", "chebyshev", ("--basis",), "Polynomial basis.",
        choices=("chebyshev", "legendre"), affects=True),
    Opt("smooth", "clip", "float", 4.0, ("--clip",),
        "Reject samples beyond K robust sigmas (0: off).", affects=True, check=_NONNEG, metavar="K"),
    Opt("smooth", "kinds", "list", (), ("--kinds",), "Kinds to fit (default: all present).", affects=True,
        metavar="KIND[,KIND]"),
    Opt("smooth", "tca_max_gap_s", "float", 30.0, ("--tca-max-gap",),
        "A TCA in a data gap longer than S s, or closer than S s to an end, is not observed.", affects=True,
        check=_POS, metavar="S"),
    # ------------------------------------------------------------------ [refine]
    # trackproc refine's options; flags that other steps also have carry a --refine- prefix
    Opt("refine", "initial", "path", None, ("--refine-initial",),
        "Stale state (JSON state file, optional covariance, or TLE: SGP4 at the traverse epoch) refined from "
        "each input's pass.", affects=True, metavar="STATE.json|TLE"),
    Opt("refine", "cost", "choice", "pointwise", ("--cost",),
        "pointwise: least squares on the samples with the stale state as a-priori; integral: seed 004 eq. 14 on "
        "the smoothed curve.", choices=("pointwise", "integral"), affects=True),
    Opt("refine", "circular", "bool", False, ("--circular/--no-circular",),
        "Impose the circular-orbit constraints of seed 004 eq. 5 (Lagrange multipliers).", affects=True),
    Opt("refine", "circular_tolerance", "float", 0.0, ("--circular-tolerance",),
        "With circular: the eccentricity to which the orbit is circular, added to the covariance (0: conditional "
        "on an exactly circular orbit).", affects=True, check=_NONNEG, metavar="E"),
    Opt("refine", "doppler_bias", "choice", "auto", ("--refine-doppler-bias",),
        "Transmitter frequency offset (and drift) to estimate; auto: offset for one-way Doppler, none for "
        "range-rate.", choices=("auto", "none", "offset", "offset+drift"), affects=True),
    Opt("refine", "apriori", "bool", None, ("--refine-apriori/--no-refine-apriori",),
        "Use the stale state as an a-priori (its covariance, else the default of docs/refine.md); unset: on for "
        "pointwise, off for integral.", affects=True),
    Opt("refine", "apriori_sigma", "map", {}, ("--refine-apriori-sigma",),
        "A-priori 1-sigma (SI) of x, vx, doppler_offset, position, velocity or state, NAME=SIGMA; overrides the "
        "stale covariance; repeatable.", affects=True, metavar="NAME=SIGMA"),
    Opt("refine", "force", "choice", "j2", ("--refine-force-model",), "Force model of the refinement.",
        choices=("two-body", "j2"), affects=True),
    Opt("refine", "earth", "choice", "wgs84", ("--refine-earth",), "Earth model of the station.",
        choices=("wgs84", "sphere"), affects=True),
    Opt("refine", "range_rate_model", "choice", None, ("--refine-range-rate-model",),
        "doppler or instantaneous (default: the pass file's metadata, else doppler).",
        choices=("doppler", "instantaneous"), affects=True),
    Opt("refine", "max_iterations", "int", 30, ("--refine-max-iterations",),
        "Gauss-Newton iterations at most; an input whose refinement does not converge fails.", affects=True,
        check=_INT_POS, metavar="N"),
    Opt("refine", "clip", "float", 4.0, ("--refine-clip",),
        "Pointwise: edit samples beyond K x max(1, WRMS) sigmas (0: off).", affects=True, check=_NONNEG,
        metavar="K"),
    Opt("refine", "reweight", "bool", True, ("--reweight/--no-reweight",),
        "Pointwise: scale the sample sigmas to their actual scatter before weighing them against the a-priori.",
        affects=True),
    Opt("refine", "output_epoch", "choice", "traverse", ("--output-epoch",),
        "Epoch of the state in passes/<name>.refined.json: the traverse point or the stale state's epoch (the "
        "file holds the other one too).", choices=("traverse", "stale"), affects=True),
    Opt("refine", "eop", "path", None, ("--refine-eop",), "IERS finals2000A file (UT1-UTC, polar motion).",
        affects=True, metavar="FILE"),
    Opt("refine", "dut1", "float", None, ("--refine-dut1",), "UT1-UTC, s, when no EOP file is given.",
        affects=True, check=(lambda v: abs(v) <= 0.9, "|UT1-UTC| <= 0.9 s"), metavar="S"),
    # ------------------------------------------------------------------ [estimate]
    Opt("estimate", "initial", "path", None, ("--initial",),
        "Initial state (JSON state file or TLE) of every window's estimate.", affects=True,
        metavar="STATE.json|TLE"),
    Opt("estimate", "window_s", "float", 0.0, ("--window",),
        "Estimate over windows of S seconds aligned on UTC (86400: one per UTC day); 0: one over all inputs.",
        affects=True, check=_NONNEG, metavar="S"),
    Opt("estimate", "min_inputs", "int", 1, ("--min-inputs",),
        "A window needs at least N processed inputs.", affects=True, check=_INT_POS, metavar="N"),
    Opt("estimate", "drop_flagged", "bool", True, ("--drop-flagged/--keep-flagged",),
        "Leave out the samples the smoother rejected (flag = true).", affects=True),
    Opt("estimate", "range_bias", "bool", False, ("--range-bias/--no-range-bias",),
        "Estimate a range bias per station with ranges.", affects=True),
    Opt("estimate", "doppler_bias", "choice", None, ("--doppler-bias",),
        "Estimate a Doppler frequency offset, or offset and drift.", choices=("offset", "offset+drift"),
        affects=True),
    Opt("estimate", "doppler_bias_per", "choice", "pass", ("--doppler-bias-per",),
        "One Doppler offset (drift) per pass or per station.", choices=("pass", "station"), affects=True),
    Opt("estimate", "angle_bias", "bool", False, ("--angle-bias/--no-angle-bias",),
        "Estimate azimuth and elevation biases per station.", affects=True),
    Opt("estimate", "apriori_sigma", "map", {}, ("--apriori-sigma",),
        "A-priori 1-sigma of a parameter or family (SI), NAME=SIGMA; repeatable.", affects=True,
        metavar="NAME=SIGMA"),
    Opt("estimate", "force", "choice", "j2", ("--force-model",),
        "Force model (trackproc estimate's --force; --force here means redo).", choices=("two-body", "j2"),
        affects=True),
    Opt("estimate", "earth", "choice", "wgs84", ("--earth",), "Earth model of the stations.",
        choices=("wgs84", "sphere"), affects=True),
    Opt("estimate", "range_rate_model", "choice", None, ("--range-rate-model",),
        "doppler or instantaneous (default: the pass files' metadata, else doppler).",
        choices=("doppler", "instantaneous"), affects=True),
    Opt("estimate", "max_iterations", "int", 20, ("--max-iterations",), "Gauss-Newton iterations at most.",
        affects=True, check=_INT_POS, metavar="N"),
    Opt("estimate", "clip", "float", 4.0, ("--estimate-clip",),
        "Edit samples beyond K x max(1, WRMS) sigmas (0: off).", affects=True, check=_NONNEG, metavar="K"),
    Opt("estimate", "kinds", "list", (), ("--estimate-kinds",), "Kinds the estimate uses (default all).",
        affects=True, metavar="KIND[,KIND]"),
    Opt("estimate", "epoch", "str", None, ("--epoch",),
        "Solution epoch: ISO 8601 UTC, initial or first (default: the initial state's).", affects=True,
        metavar="ISO|initial|first"),
    Opt("estimate", "eop", "path", None, ("--eop",), "IERS finals2000A file (UT1-UTC, polar motion).",
        affects=True, metavar="FILE"),
    Opt("estimate", "dut1", "float", None, ("--dut1",), "UT1-UTC, s, when no EOP file is given.", affects=True,
        metavar="S"),
)

BY_NAME: dict[str, Opt] = {o.name: o for o in SCHEMA}


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
        "choice": " or ".join(opt.choices), "degree": "an integer >= 0 or auto",
        "map": "NAME=VALUE pairs with numeric values",
    }[opt.kind]


def _split(text: str) -> list:
    return [part.strip() for part in text.split(",") if part.strip()]


def convert(opt: Opt, value, origin: str, config_file: Optional[str] = None, base_dir: Optional[str] = None):
    """``value`` (TOML value, environment text or flag value) as the type of ``opt``.

    Text (environment, flags) is parsed; TOML values must already have the right type.
    Relative paths are joined to ``base_dir`` (the config file's directory for config values).
    Raises :class:`InputError` (exit 2) naming the key, flag or variable.
    """
    text = origin in ("env", "flag")

    def bad(found=value, expected=None):
        return InputError("invalid setting", found=found, expected=expected or _expected(opt),
                          **_where(opt, origin, config_file))

    if value is None:
        return None
    kind = opt.kind
    if kind in ("str", "path", "choice"):
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
    if kind in ("list", "paths"):
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
        if kind == "paths":
            items = [_path(item, base_dir) for item in items]
        return tuple(items)
    if kind == "bool":
        if isinstance(value, bool):
            return value
        if isinstance(value, str) and text and value.strip().lower() in _TRUE | _FALSE:
            return value.strip().lower() in _TRUE
        raise bad()
    if kind == "int":
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
    if kind == "float":
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
    if kind == "degree":
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
    if kind == "map":
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
    raise AssertionError(kind)  # pragma: no cover


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
        import tomllib
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
    import difflib

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


def documentation_table() -> str:
    """Markdown table of every setting: config key, flag, environment variable, default, meaning."""
    rows = ["| config key | flag | environment variable | default | meaning |", "|---|---|---|---|---|"]
    for opt in SCHEMA:
        default = opt.default
        if isinstance(default, tuple):
            default = ", ".join(default) if default else "(none)"
        elif isinstance(default, dict):
            default = "(none)"
        elif default is None:
            default = "(none)"
        elif isinstance(default, bool):
            default = str(default).lower()
        flags = " / ".join(f"`{f}`" for f in opt.flags)
        rows.append(f"| `{opt.name}` | {flags} | `{opt.env}` | {default} | {opt.help} |")
    return "\n".join(rows) + "\n"


__all__ = ["SCHEMA", "BY_NAME", "Opt", "Settings", "resolve", "convert", "load_toml", "documentation_table",
           "CONFIG_ENV", "ENV_PREFIX", "DEFAULT_PATTERNS", "SECTIONS"]

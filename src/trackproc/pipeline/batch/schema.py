"""The settings of ``trackproc batch``: one schema for the TOML file, the flags and the environment.

Every setting is a key of a TOML section (``[batch]``, ``[ingest]``, ``[smooth]``,
``[refine]``, ``[estimate]``, ``[filter]``), a command-line flag and an environment variable, resolved in this order:

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
from dataclasses import dataclass
from typing import Any, Optional

from trackproc.vocabulary import NOISE_MODELS, RANGE_RATE_MODELS

#: Sections in the order they are documented; ``batch`` holds the run options.
SECTIONS = ("batch", "ingest", "smooth", "refine", "estimate", "filter")
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

    ``kind``: str | path | paths (list of paths or globs) | list (of str) | int | float | duration
    (seconds, or a number with s, m, h, d) | bool |
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
        "Output directory: passes/, estimates/, filter/, summary.json, summary.csv, report.html, the lock file.", metavar="DIR"),
    Opt("batch", "steps", "list", ("ingest", "smooth"), ("--steps",),
        "The chain, comma separated, in order: ingest, smooth, refine, estimate, filter.",
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
    Opt("batch", "wait_timeout_s", "duration", 0.0, ("--wait-timeout",),
        "Give up waiting for the lock after S seconds (0: wait as long as it takes).", check=_NONNEG,
        metavar="S"),
    Opt("batch", "strict", "bool", False, ("--strict/--no-strict",),
        "A refined or estimated solution whose quality verdict is suspect makes the run exit 3 (1 when "
        "nothing else succeeded), as a rejected one always does; the outputs are written either way."),
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
    Opt("ingest", "max_gap_s", "duration", 300.0, ("--max-gap",),
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
    Opt("smooth", "tca_max_gap_s", "duration", 30.0, ("--tca-max-gap",),
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
        "With circular: the eccentricity to which the orbit is circular; the constraints hold to it (0: exact, "
        "covariance conditional on an exactly circular orbit).", affects=True, check=_NONNEG, metavar="E"),
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
        choices=RANGE_RATE_MODELS, affects=True),
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
    Opt("estimate", "window_s", "duration", 0.0, ("--window",),
        "Estimate over windows of S seconds aligned on UTC (86400: one per UTC day); 0: one over all inputs.",
        affects=True, check=_NONNEG, metavar="S"),
    Opt("estimate", "min_inputs", "int", 1, ("--min-inputs",),
        "A window needs at least N processed inputs.", affects=True, check=_INT_POS, metavar="N"),
    Opt("estimate", "drop_flagged", "bool", True, ("--drop-flagged/--keep-flagged",),
        "Leave out the samples the smoother rejected (flag = true).", affects=True),
    Opt("estimate", "range_bias", "bool", False, ("--range-bias/--no-range-bias",),
        "Estimate a range bias per station with ranges.", affects=True),
    Opt("estimate", "doppler_bias", "choice", "auto", ("--doppler-bias",),
        "Transmitter frequency parameters: auto = offset and drift for each pass of one-way Doppler; none; or "
        "offset / offset+drift on every Doppler or range-rate pass.",
        choices=("auto", "none", "offset", "offset+drift"),
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
        choices=RANGE_RATE_MODELS, affects=True),
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
    # ------------------------------------------------------------------ [filter]
    Opt("filter", "initial", "path", None, ("--filter-initial",),
        "Initial state (JSON state file with a covariance, or TLE) of the filter's first run; later runs start "
        "from the carried state (filter.state).", affects=True, metavar="STATE.json|TLE"),
    Opt("filter", "state", "path", None, ("--filter-state",),
        "The carried state: read as the initial state when it exists, replaced by each run's output "
        "(default OUTPUT/filter/state.json).", metavar="STATE.json"),
    Opt("filter", "drop_flagged", "bool", True, ("--filter-drop-flagged/--filter-keep-flagged",),
        "Leave out the samples the smoother rejected (flag = true).", affects=True),
    Opt("filter", "range_bias", "bool", False, ("--filter-range-bias/--no-filter-range-bias",),
        "A range bias state per station with ranges.", affects=True),
    Opt("filter", "doppler_bias", "choice", "auto", ("--filter-doppler-bias",),
        "Transmitter frequency states, as estimate's.", choices=("auto", "none", "offset", "offset+drift"),
        affects=True),
    Opt("filter", "apriori_sigma", "map", {}, ("--filter-apriori-sigma",),
        "Initial 1-sigma of a parameter or family (SI), NAME=SIGMA; repeatable.", affects=True,
        metavar="NAME=SIGMA"),
    Opt("filter", "snc_accel", "float", 0.0, ("--filter-snc-accel",),
        "State noise compensation: 1-sigma density of a white acceleration on each RTN axis, m/s^2/sqrt(Hz).",
        affects=True, check=_NONNEG, metavar="Q"),
    Opt("filter", "oscillator_noise", "float", 0.0, ("--filter-oscillator-noise",),
        "Random walk of the transmitter frequency offset, Hz/sqrt(s).", affects=True, check=_NONNEG,
        metavar="HZ_PER_SQRT_S"),
    Opt("filter", "noise", "choice", "auto", ("--filter-noise",),
        "Noise model of each pass's Doppler/range-rate samples, as filter's --noise (auto: chosen per pass by "
        "REML).", choices=NOISE_MODELS, affects=True),
    Opt("filter", "edit_sigma", "float", 5.0, ("--filter-edit-sigma",),
        "Edit a sample whose innovation is beyond K sigmas (0: off).", affects=True, check=_NONNEG, metavar="K"),
    Opt("filter", "force", "choice", "j2", ("--filter-force-model",), "Force model.",
        choices=("two-body", "j2"), affects=True),
    Opt("filter", "kinds", "list", (), ("--filter-kinds",), "Kinds the filter uses (default all).",
        affects=True, metavar="KIND[,KIND]"),
    Opt("filter", "range_rate_model", "choice", None, ("--filter-range-rate-model",),
        "doppler or instantaneous (default: the pass files' metadata, else doppler).",
        choices=RANGE_RATE_MODELS, affects=True),
    Opt("filter", "eop", "path", None, ("--filter-eop",), "IERS finals2000A file (UT1-UTC, polar motion).",
        affects=True, metavar="FILE"),
    Opt("filter", "dut1", "float", None, ("--filter-dut1",), "UT1-UTC, s, when no EOP file is given.",
        affects=True, check=(lambda v: abs(v) <= 0.9, "|UT1-UTC| <= 0.9 s"), metavar="S"),
)

BY_NAME: dict[str, Opt] = {o.name: o for o in SCHEMA}


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

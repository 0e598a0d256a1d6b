"""The options of the full force model (``--force full``), defined once for every command
that propagates: ``--gravity DEG[xORD]``, ``--gravity-field FILE.gfc``, ``--third-body``,
``--srp/--no-srp``, ``--drag/--no-drag``, ``--atmosphere`` (NRLMSIS's ``--f107``, ``--f107a``, ``--ap``),
``--relativity/--no-relativity``, and the spacecraft (``--mass-kg``, ``--srp-area-m2``, ``--cr``, ``--drag-area-m2``, ``--cd``,
else the state file's ``spacecraft: {...}``).

A command takes them all by one decorator, :func:`force_options`, placed under
``@app.command``: the options join the command's signature (typer reads it) and reach the
function as one :class:`ForceSettings` (keyword ``force_settings``). Nothing heavy is
imported here (``--help`` stays fast); :meth:`ForceSettings.model` builds the
:class:`~trackproc.dynamics.forces.ForceModel`.
"""

from __future__ import annotations

import functools
import inspect
import typing
from dataclasses import dataclass, fields
from typing import Optional

import typer

from trackproc import vocabulary
from trackproc.cli.common import choices

Atmosphere = choices("Atmosphere", vocabulary.ATMOSPHERES)
PANEL = "Force model (--force full)"

#: The options, by parameter name: (default typer.Option, annotation).
OPTIONS = {
    "gravity": (typer.Option("20", "--gravity", metavar="DEG[xORD]", rich_help_panel=PANEL,
                             help="--force full: degree and order of the gravity field (default 20; 20x0: zonals)."),
                str),
    "gravity_field": (typer.Option(None, "--gravity-field", metavar="FILE.gfc", rich_help_panel=PANEL,
                                   help="--force full: ICGEM gravity-field file (default: the shipped EIGEN-6S, "
                                        "to degree 70)."),
                      Optional[str]),
    "third_body": (typer.Option("sun,moon", "--third-body", metavar="sun,moon|none", rich_help_panel=PANEL,
                                help="--force full: third bodies (ERFA's Sun and Moon)."),
                   str),
    "srp": (typer.Option(None, "--srp/--no-srp", rich_help_panel=PANEL, show_default=False,
                         help="--force full: solar radiation pressure (default: on when mass and SRP area are "
                              "known)."),
            Optional[bool]),
    "drag": (typer.Option(None, "--drag/--no-drag", rich_help_panel=PANEL, show_default=False,
                          help="--force full: atmospheric drag (default: on when mass and drag area are known)."),
             Optional[bool]),
    "atmosphere": (typer.Option(Atmosphere.harris_priester, "--atmosphere", rich_help_panel=PANEL,
                                help="--force full: density model of the drag (nrlmsis needs pymsis)."),
                   Atmosphere),
    "relativity": (typer.Option(True, "--relativity/--no-relativity", rich_help_panel=PANEL,
                                help="--force full: Schwarzschild correction."),
                   bool),
    "mass_kg": (typer.Option(None, "--mass-kg", metavar="KG", rich_help_panel=PANEL,
                             help="Spacecraft mass, kg (else the state file's spacecraft.mass_kg)."),
                Optional[float]),
    "srp_area_m2": (typer.Option(None, "--srp-area-m2", metavar="M2", rich_help_panel=PANEL,
                                 help="Cross-section for radiation pressure, m²."),
                    Optional[float]),
    "cr": (typer.Option(None, "--cr", metavar="CR", rich_help_panel=PANEL,
                        help="Radiation-pressure coefficient (default 1.5)."),
           Optional[float]),
    "drag_area_m2": (typer.Option(None, "--drag-area-m2", metavar="M2", rich_help_panel=PANEL,
                                  help="Cross-section for drag, m²."),
                     Optional[float]),
    "cd": (typer.Option(None, "--cd", metavar="CD", rich_help_panel=PANEL, help="Drag coefficient (default 2.2)."),
           Optional[float]),
    "f107": (typer.Option(None, "--f107", metavar="SFU", rich_help_panel=PANEL,
                          help="--atmosphere nrlmsis: F10.7 solar flux of the previous day (default 150)."),
             Optional[float]),
    "f107a": (typer.Option(None, "--f107a", metavar="SFU", rich_help_panel=PANEL,
                           help="--atmosphere nrlmsis: 81-day mean F10.7 (default 150)."),
              Optional[float]),
    "ap": (typer.Option(None, "--ap", metavar="AP", rich_help_panel=PANEL,
                        help="--atmosphere nrlmsis: daily geomagnetic Ap (default 4)."),
           Optional[float]),
}
_SPACECRAFT_KEYS = ("mass_kg", "srp_area_m2", "cr", "drag_area_m2", "cd")
_SPACE_WEATHER_KEYS = ("f107", "f107a", "ap")
#: Plausible spacecraft properties (inclusive): 10 g (a femtosatellite) to 1e6 kg (the ISS is
#: 4.2e5 kg), areas up to 1e4 m^2; Cr = 1 + reflectivity is 1 to 2 for a sphere (fitted values
#: stray a little), Cd 1.5 to 3.5 in free molecular flow (fitted values stray further).
SPACECRAFT_RANGES = {"mass_kg": (0.01, 1.0e6), "srp_area_m2": (1e-4, 1.0e4), "drag_area_m2": (1e-4, 1.0e4),
                     "cr": (0.5, 3.0), "cd": (0.5, 5.0)}
#: Largest plausible area-to-mass ratio, m^2/kg (thin blankets of debris and solar sails reach
#: ~30; a satellite is 0.001 to 0.05).
MAX_AREA_TO_MASS = 100.0


def _spacecraft_problem(key: str, value) -> str | None:
    """Why ``value`` is not a plausible ``key`` (None when it is)."""
    low, high = SPACECRAFT_RANGES[key]
    if isinstance(value, bool) or not isinstance(value, (int, float)) or not (low <= value <= high):
        unit = {"mass_kg": " kg", "srp_area_m2": " m^2", "drag_area_m2": " m^2"}.get(key, "")
        return f"a number from {low:g} to {high:g}{unit}"
    return None   # NRLMSIS's fixed space weather (ForceModel fields)


@dataclass
class ForceSettings:
    """The full-force options as given on the command line (None = not given)."""

    gravity: str = "20"
    gravity_field: Optional[str] = None
    third_body: str = "sun,moon"
    srp: Optional[bool] = None
    drag: Optional[bool] = None
    atmosphere: object = "harris-priester"
    relativity: bool = True
    mass_kg: Optional[float] = None
    srp_area_m2: Optional[float] = None
    cr: Optional[float] = None
    drag_area_m2: Optional[float] = None
    cd: Optional[float] = None
    f107: Optional[float] = None
    f107a: Optional[float] = None
    ap: Optional[float] = None

    def given(self) -> list[str]:
        """Flags given that only ``--force full`` uses."""
        default = ForceSettings()
        out = []
        for f in fields(self):
            value = getattr(self, f.name)
            value = getattr(value, "value", value)
            if value != getattr(default, f.name):
                out.append("--" + f.name.replace("_", "-"))
        return out

    def degree_order(self) -> tuple[int, int]:
        text = str(self.gravity).lower().strip()
        deg, _, order = text.partition("x")
        try:
            d = int(deg)
            o = int(order) if order else d
        except ValueError:
            raise typer.BadParameter(f"expected DEG or DEGxORD (e.g. 20 or 70x70), got {self.gravity!r}",
                                     param_hint="--gravity") from None
        if not (0 <= o <= d):
            raise typer.BadParameter(f"expected 0 <= order <= degree, got {self.gravity!r}", param_hint="--gravity")
        from trackproc.constants import MAX_GRAVITY_DEGREE

        if d > MAX_GRAVITY_DEGREE:
            raise typer.BadParameter(f"degree {d} is above {MAX_GRAVITY_DEGREE}, the highest this force model "
                                     "evaluates (terms beyond it are below 1e-13 of the central term at 200 km "
                                     "altitude, and each costs memory per evaluated point)", param_hint="--gravity")
        return d, o

    def bodies(self) -> tuple:
        text = self.third_body.strip().lower()
        if text == "none":
            return ()
        names = tuple(x.strip() for x in text.split(",") if x.strip())
        bad = [n for n in names if n not in vocabulary.THIRD_BODIES]
        if bad or not names or len(set(names)) != len(names):
            raise typer.BadParameter(f"expected sun, moon, sun,moon or none, got {self.third_body!r}",
                                     param_hint="--third-body")
        return names

    def model(self, force: str, epoch, eop=None, state=None, estimated: tuple = ()):
        """The :class:`~trackproc.dynamics.forces.ForceModel` for ``--force full`` (None for
        another force; full-only flags with another force are a usage error).

        ``epoch`` dates the field's time-variable terms; ``state`` (a read state file) may
        carry ``spacecraft: {mass_kg, srp_area_m2, cr, drag_area_m2, cd}``.
        """
        if force != "full":
            extra = self.given()
            if extra:
                raise typer.BadParameter(f"{', '.join(extra)}: only with --force full (--force is {force})",
                                         param_hint=extra[0])
            return None
        from trackproc.dynamics.forces import ForceModel, Spacecraft
        from trackproc.errors import InputError
        from trackproc.io.icgem import load_field

        deg, order = self.degree_order()
        bodies = self.bodies()
        sc = spacecraft_from_state(state)
        for key in _SPACECRAFT_KEYS:
            value = getattr(self, key)
            if value is not None:
                problem = _spacecraft_problem(key, value)
                if problem:
                    raise typer.BadParameter(f"expected {problem}, got {value}",
                                             param_hint="--" + key.replace("_", "-"))
                sc[key] = float(value)
        for area in ("srp_area_m2", "drag_area_m2"):
            if sc.get(area) is not None and sc.get("mass_kg") is not None \
                    and sc[area] / sc["mass_kg"] > MAX_AREA_TO_MASS:
                flag = "--" + area.replace("_", "-")
                raise typer.BadParameter(f"area-to-mass ratio {sc[area] / sc['mass_kg']:.4g} m^2/kg ({flag} "
                                         f"{sc[area]:g} over --mass-kg {sc['mass_kg']:g}, command line or state "
                                         f"file); expected at most {MAX_AREA_TO_MASS:g} m^2/kg", param_hint=flag)
        spacecraft = Spacecraft(**sc)
        srp = spacecraft.srp_known if self.srp is None else self.srp
        drag = spacecraft.drag_known if self.drag is None else self.drag
        if srp and not spacecraft.srp_known:
            raise typer.BadParameter("radiation pressure needs the spacecraft mass and SRP area (--mass-kg, "
                                     "--srp-area-m2, or spacecraft: in the state file)", param_hint="--srp")
        if drag and not spacecraft.drag_known:
            raise typer.BadParameter("drag needs the spacecraft mass and drag area (--mass-kg, --drag-area-m2, or "
                                     "spacecraft: in the state file)", param_hint="--drag")
        atmosphere = getattr(self.atmosphere, "value", self.atmosphere)
        weather = {}
        for key in _SPACE_WEATHER_KEYS:
            value = getattr(self, key)
            if value is None:
                continue
            flag = "--" + key.replace("_", "-")
            if not (drag and atmosphere == "nrlmsis"):
                raise typer.BadParameter("only with --drag --atmosphere nrlmsis", param_hint=flag)
            if not (0 <= value < float("inf")) or (key != "ap" and value == 0):
                raise typer.BadParameter(f"expected a {'non-negative' if key == 'ap' else 'positive'} number, "
                                         f"got {value}", param_hint=flag)
            weather[key] = float(value)
        if drag and atmosphere == "nrlmsis":
            import importlib.util

            if importlib.util.find_spec("pymsis") is None:
                raise typer.BadParameter("nrlmsis needs the pymsis package (pip install pymsis)",
                                         param_hint="--atmosphere")
        field = load_field(self.gravity_field, deg, order, date=epoch)
        try:
            return ForceModel(field=field, third_bodies=bodies, srp=srp, drag=drag, relativity=self.relativity,
                              spacecraft=spacecraft, atmosphere=atmosphere, estimated=tuple(estimated), eop=eop,
                              **weather, **empirical_from_state(state))
        except ValueError as exc:
            raise InputError(str(exc), column="--force") from None


def spacecraft_from_state(state) -> dict:
    """The ``spacecraft`` block of a state file (``State.extra``) as keyword arguments; an
    :class:`~trackproc.errors.InputError` naming the file and field when malformed."""
    from trackproc.errors import InputError

    block = (getattr(state, "extra", None) or {}).get("spacecraft") if state is not None else None
    if block is None:
        return {}
    source = getattr(state, "source", None) or "<state>"
    if not isinstance(block, dict):
        raise InputError("not an object", file=source, column="spacecraft", found=block,
                         expected="{mass_kg, srp_area_m2, cr, drag_area_m2, cd}")
    out = {}
    for key, value in block.items():
        if key not in _SPACECRAFT_KEYS:
            raise InputError("unknown key", file=source, column=f"spacecraft.{key}", found=key,
                             expected=", ".join(_SPACECRAFT_KEYS))
        if value is None:
            continue
        problem = _spacecraft_problem(key, value)
        if problem:
            raise InputError("implausible value", file=source, column=f"spacecraft.{key}", found=value,
                             expected=problem)
        out[key] = float(value)
    return out


#: The empirical accelerations of a state file's ``constants`` (as estimate writes them, the
#: ForceModel.describe keys) and the ForceModel fields they set.
_EMPIRICAL_KEYS = {"empirical_rtn_m_s2": "empirical_rtn", "empirical_gcrf_m_s2": "empirical_gcrf",
                   "empirical_gcrf_rate_m_s3": "empirical_gcrf_rate"}


def empirical_from_state(state) -> dict:
    """The empirical accelerations of a state file's ``constants`` (``empirical_rtn_m_s2``,
    ``empirical_gcrf_m_s2``, ``empirical_gcrf_rate_m_s3``: estimate --estimate-force writes its
    values there) as ForceModel keyword arguments, so that a solution propagates with the forces
    it was fitted with; an :class:`~trackproc.errors.InputError` naming the field when malformed."""
    import math

    from trackproc.errors import InputError

    constants = getattr(state, "constants", None) or {} if state is not None else {}
    if not isinstance(constants, dict):
        return {}
    source = getattr(state, "source", None) or "<state>"
    out = {}
    for key, name in _EMPIRICAL_KEYS.items():
        value = constants.get(key)
        if value is None:
            continue
        ok = (isinstance(value, (list, tuple)) and len(value) == 3
              and all(isinstance(x, (int, float)) and not isinstance(x, bool) and math.isfinite(x) for x in value))
        if not ok:
            raise InputError("bad value", file=source, column=f"constants.{key}", found=value,
                             expected="three finite numbers")
        out[name] = tuple(float(x) for x in value)
    return out


def force_options(fn):
    """Add the full-force options to a command; the function gets ``force_settings``."""
    sig = inspect.signature(fn)
    params = [p for p in sig.parameters.values() if p.name != "force_settings"]
    extra = [inspect.Parameter(name, inspect.Parameter.KEYWORD_ONLY, default=opt, annotation=ann)
             for name, (opt, ann) in OPTIONS.items()]
    # keyword-only parameters must follow positional-or-keyword ones in a signature
    params = [p.replace(kind=inspect.Parameter.KEYWORD_ONLY) for p in params]

    @functools.wraps(fn)
    def wrapper(*args, **kwargs):
        settings = ForceSettings(**{name: kwargs.pop(name) for name in OPTIONS if name in kwargs})
        return fn(*args, force_settings=settings, **kwargs)

    wrapper.__signature__ = sig.replace(parameters=params + extra)
    hints = typing.get_type_hints(fn)            # resolved in the command's module
    hints.pop("force_settings", None)
    hints.update({name: ann for name, (_, ann) in OPTIONS.items()})
    wrapper.__annotations__ = hints
    return wrapper


def full_force_model(force_settings, orbit, force, orientation):
    """The ForceModel of ``--force full`` for a STATE|TLE argument (None for another force; the
    full-only options with another force are a usage error)."""
    from trackproc.io.tle import tle_epoch
    from trackproc.pipeline.orbit_source import resolve_force

    key = resolve_force(orbit, force.value if force is not None else None, allow_full=True)
    epoch = orbit.state.epoch if orbit.state is not None else tle_epoch(orbit.tle)
    return force_settings.model(key, epoch, orientation, orbit.state)

"""What a ``STATE|TLE`` argument names, as GCRF states at any UTC times, and a station's
observables of it (shared by ``propagate``, ``passes``, ``compare`` and ``fit-tle``).

* A TLE is evaluated by SGP4 at every requested time (:func:`trackproc.io.tle.sgp4_teme`, then
  TEME -> GCRF by :func:`trackproc.dynamics.frames.teme_to_gcrf`): mean elements are only
  meaningful through the theory they were fitted with, so integrating the TLE's osculating
  state with another force model drifts by kilometres a day (issue 18: 16.3 Hz RMS instead of
  4.7 Hz on a pass 41 h after the epoch).
* A state (or a TLE with ``force`` two-body/j2) is integrated once by the Taylor engine
  (:func:`trackproc.dynamics.propagator.propagate_state`) over the requested interval and read
  from its dense output.

Observables (one-way light time, range, range-rate, Doppler, azimuth, elevation) are the
foundation model :func:`trackproc.models.measurements.observables` (the one ``simulate`` uses),
fed with the satellite's acceleration and jerk at the reception time; for SGP4 these come from
central differences of its velocity over ``FD_STEP_S`` (their error moves the emission-time
state by far below a micrometre over a LEO light time of a few milliseconds).
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import Optional

import numpy as np

from trackproc.dynamics import frames, geodesy, propagator, timescales as ts
from trackproc.dynamics.timescales import datetime64_to_jd_utc
from trackproc.errors import InputError, ProcessingError
from trackproc.io.atomic import is_stdio, read_input_bytes
from trackproc.io.statefile import is_state_json, parse_state, read_state_or_tle
from trackproc.io.tle import parse_tle, sgp4_teme, tle_epoch, tle_state
from trackproc.models.measurements import observables, station_gcrf
from trackproc.io.statefile import parse_epoch
from trackproc.io.columns import sniff_container
from trackproc.io.passfile import parse_pass_table

DEG = np.pi / 180.0
#: Step of the central differences giving SGP4's acceleration and jerk, s.
FD_STEP_S = 1.0
#: Force models of a ``STATE|TLE`` argument (``--force``).
FORCES = ("sgp4", "two-body", "j2", "full")
SGP4_LABEL = "SGP4 (TLE mean elements, WGS-72; Vallado's sgp4 package), TEME -> GCRF via ITRF"


@dataclass
class OrbitInput:
    """A read ``STATE|TLE`` argument: exactly one of ``state`` (GCRF) or ``tle``; ``pass_table``
    is the pass file the TLE came from (``metadata:PASS``, or a pass file given as the orbit),
    whose stations a command may use."""

    state: Optional[object] = None
    tle: Optional[object] = None
    source: str = "<orbit>"
    pass_table: Optional[object] = None


#: ``metadata:PASS`` names the TLE stored in the pass file PASS (DopTrack), wherever an orbit is read.
METADATA_PREFIX = "metadata:"


def metadata_path(spec: str) -> Optional[str]:
    """The pass file of a ``metadata:PASS`` argument, else None."""
    spec = str(spec)
    if spec.startswith(METADATA_PREFIX):
        path = spec[len(METADATA_PREFIX):]
        if not path:
            raise InputError("no pass file after 'metadata:'", found=spec,
                             expected="metadata:PASS.parquet (the pass file whose metadata holds the TLE)")
        return path
    return None


def orbit_from_pass(table, source: str) -> OrbitInput:
    """The TLE of a pass file's metadata as an :class:`OrbitInput` (its stations kept)."""
    tle = tle_from_pass_metadata(table, source)
    return OrbitInput(tle=tle, source=tle.source, pass_table=table)


def read_orbit(path: str, eop=None) -> OrbitInput:
    """A JSON state file or a 2/3-line TLE (``-`` = stdin), told apart by the first character; or
    the TLE a pass file's metadata holds, for ``metadata:PASS`` or a Parquet/Arrow pass file."""

    spec = metadata_path(path)
    source = "<stdin>" if is_stdio(spec or path) else str(spec or path)
    data = read_input_bytes(spec or path)
    if spec is not None or sniff_container(data) != "text":
        return orbit_from_pass(parse_pass_table(data, source), source)
    if is_state_json(data):
        return OrbitInput(state=parse_state(data, source, eop), source=source)
    return OrbitInput(tle=parse_tle(data.decode("utf-8", errors="replace"), source), source=source)


def tle_from_pass_metadata(table, source: str = "<pass>"):
    """The TLE a pass file's metadata carries (DopTrack's ``doptrack.<file>.tle``, or a top-level
    ``tle``): the prediction the station itself used. All sources must carry the same one."""

    found = []
    meta = table.meta or {}
    if isinstance(meta.get("tle"), list):
        found.append(tuple(meta["tle"]))
    for entry in (meta.get("doptrack") or {}).values():
        if isinstance(entry, dict) and isinstance(entry.get("tle"), list):
            found.append(tuple(entry["tle"]))
    unique = sorted(set(found))
    if not unique:
        raise InputError("no TLE in the pass file's metadata", file=source, column="tle",
                         expected="a pass file ingested from DopTrack (its TLE kept), or a TLE/state file")
    if len(unique) > 1:
        raise InputError("the pass file's sources carry different TLEs", file=source, column="tle",
                         found=f"{len(unique)} TLEs", expected="one TLE (compare the passes one at a time)")
    return parse_tle("\n".join(unique[0]), f"{source} (metadata TLE)")


def metadata_tle(tables: list):
    """``--initial metadata``: the TLE stored in the pass files' metadata (DopTrack), the newest
    by epoch when several files carry different ones (the best-informed prediction);
    ``tables`` are ``(source, PassTable)``. InputError when none carries a TLE."""

    found, errors = [], []
    for source, table in tables:
        try:
            found.append(tle_from_pass_metadata(table, source))
        except InputError as exc:
            errors.append(exc)
    if not found:
        if len(errors) == 1:
            raise errors[0]
        raise InputError("no TLE in the pass files' metadata", column="--initial", found="metadata",
                         expected="pass files ingested from DopTrack (their TLE kept), or a TLE/state file")
    return max(found, key=lambda t: (tle_epoch(t), t.line1))


def initial_orbit(initial: str, tables: list, eop=None) -> OrbitInput:
    """``--initial STATE.json|TLE|metadata`` of ``fit-tle``: an :class:`OrbitInput`."""
    if initial == "metadata":
        tle = metadata_tle(tables)
        return OrbitInput(tle=tle, source=tle.source)
    return read_orbit(initial, eop)


def initial_state(initial: str, tables: list, eop=None, at=None):
    """``--initial STATE.json|TLE|metadata[:PASS]`` of ``refine`` and ``estimate``: a GCRF state (a
    TLE, given or from the pass files' metadata, by SGP4 at its epoch or at ``at``)."""

    if initial == "metadata":
        return tle_state(metadata_tle(tables), at=at, eop=eop)
    if metadata_path(initial) is not None:
        return tle_state(read_orbit(initial, eop).tle, at=at, eop=eop)
    return read_state_or_tle(initial, eop, at=at)


def tle_evaluation_epoch(epoch: Optional[str], tables: list, column: str = "--epoch"):
    """Where ``estimate`` evaluates a TLE given as its initial state: at ``epoch`` (ISO time), at
    the TLE's own epoch (``initial``), else at the first sample (``first``, and the default: SGP4's
    state at the data, rather than the state at the TLE's epoch carried to the data by another
    force model, which on a LEO TLE a day old costs kilometres of drag). ``None``: the TLE's epoch."""
    if epoch is not None and epoch.lower() == "initial":
        return None
    if epoch is not None and epoch.lower() != "first":
        return parse_epoch(epoch, column=column)
    times = [t.column("time") for _, t in tables]
    return min((x.min() for x in times if x.size), default=np.datetime64("NaT", "ns"))


def resolve_force(orbit: OrbitInput, force: Optional[str], allow_full: bool = False) -> str:
    """``--force``: default ``sgp4`` for a TLE, ``j2`` for a state; ``sgp4`` needs a TLE;
    ``full`` only where the command builds the full force model (``allow_full``)."""
    if force is None:
        return "sgp4" if orbit.tle is not None else "j2"
    if force not in FORCES:
        raise InputError("unknown force model", column="--force", found=force, expected=", ".join(FORCES))
    if force == "full" and not allow_full:
        raise InputError("not offered by this command", column="--force", found="full",
                         expected="sgp4, j2 or two-body (--force full: propagate, passes, compare, simulate, accuracy, estimate)")
    if force == "sgp4" and orbit.tle is None:
        raise InputError("SGP4 needs a TLE", file=orbit.source, column="--force", found="sgp4",
                         expected="a TLE input, or --force j2 / two-body for a state file")
    return force


def sgp4_states(tle, times, eop=None) -> np.ndarray:
    """GCRF states ``[r m, v m/s]`` (N, 6) of a TLE by SGP4 at UTC ``datetime64`` times."""

    jd1, jd2 = datetime64_to_jd_utc(np.asarray(times, dtype="datetime64[ns]").reshape(-1))
    r_teme, v_teme = sgp4_teme(tle, jd1, jd2)
    r, v = frames.teme_to_gcrf(r_teme, v_teme, jd1, jd2, eop)
    return np.concatenate([r, v], axis=1)


class Satellite:
    """GCRF position, velocity, acceleration and jerk at UTC times ``t0 + t_s`` for one orbit.

    Built once for an interval ``[t0 + lo_s, t0 + hi_s]``; :meth:`rvaj` takes seconds from
    ``t0`` (SI seconds, leap seconds counted). ``force`` is ``sgp4`` (a TLE), ``two-body`` or
    ``j2`` (a state; a TLE is first turned into its SGP4 state at ``t0``).
    """

    def __init__(self, orbit: OrbitInput, force: str, t0, lo_s: float, hi_s: float, eop=None, tol: float = 1e-13,
                 force_model=None):
        self.force, self.eop = force, eop
        self.t0 = np.datetime64(t0, "ns")
        self.jd0 = tuple(float(x) for x in ts.datetime64_to_jd_utc(self.t0))
        self.tle = orbit.tle if force == "sgp4" else None
        self.traj = None
        self.initial = orbit.state
        if force != "sgp4":
            if orbit.state is None:
                self.initial = tle_state(orbit.tle, at=self.t0, eop=eop)
            shift = float(ts.seconds_since(self.jd0, self.initial.jd_utc))
            margin = 4 * FD_STEP_S
            span = np.array([lo_s - margin, hi_s + margin]) + shift
            try:
                traj = propagator.propagate_state(self.initial, span, force=force, eop=eop,
                                                  tol=tol if force_model is None else 1e-12, force_model=force_model)
            except (ValueError, ArithmeticError) as exc:
                raise ProcessingError(f"propagation failed: {exc}") from None
            self.traj = traj.raise_for_outcome()
            self._shift = shift

    def times(self, t_s) -> np.ndarray:
        """UTC ``datetime64[ns]`` of seconds from ``t0``."""

        return ts.jd_utc_to_datetime64(*ts.add_seconds_utc(self.jd0, np.atleast_1d(np.asarray(t_s, float))))

    def states(self, t_s) -> np.ndarray:
        """GCRF states ``[r m, v m/s]`` (N, 6) at seconds from ``t0``."""
        return self._states(t_s)

    def _states(self, t_s) -> np.ndarray:
        if self.traj is not None:
            return self.traj.state(np.asarray(t_s, float) + self._shift)
        return sgp4_states(self.tle, self.times(t_s), self.eop)

    def rvaj(self, t_s):
        """Position, velocity, acceleration, jerk (each (N, 3), GCRF SI) at seconds from ``t0``."""
        t = np.atleast_1d(np.asarray(t_s, float))
        h = FD_STEP_S
        if self.traj is not None:
            x = self.traj.state(t + self._shift)
            acc = self.traj.state(np.concatenate([t - h, t, t + h]) + self._shift, derivative=1)[:, 3:]
            a_m, a_0, a_p = np.split(acc, 3)
            return x[:, :3], x[:, 3:], a_0, (a_p - a_m) / (2 * h)
        return _rvaj_from_states(self._states(np.concatenate([t - h, t, t + h])), h)


def _rvaj_from_states(x, h):
    """Position, velocity, and by central differences of the velocity over ``h`` the
    acceleration and jerk, from states stacked ``[t - h; t; t + h]`` (3N, 6)."""
    x_m, x_0, x_p = np.split(x, 3)
    a = (x_p[:, 3:] - x_m[:, 3:]) / (2 * h)
    j = (x_p[:, 3:] - 2 * x_0[:, 3:] + x_m[:, 3:]) / (h * h)
    return x_0[:, :3], x_0[:, 3:], a, j


def teme_to_gcrf_maps(jd1, jd2, eop=None) -> np.ndarray:
    """The 6 x 6 matrices (N, 6, 6) taking a TEME state ``[r, v]`` to GCRF at each UTC date:
    :func:`trackproc.dynamics.frames.teme_to_gcrf` is linear in the state, so it is evaluated
    once on the six unit states and reused for any number of element sets."""

    jd1, jd2 = (np.atleast_1d(np.asarray(a, float)) for a in (jd1, jd2))
    basis = np.broadcast_to(np.eye(6)[:, None, :], (6, jd1.size, 6))
    r, v = frames.teme_to_gcrf(basis[..., :3], basis[..., 3:], jd1, jd2, eop)
    return np.transpose(np.concatenate([r, v], -1), (1, 2, 0))


class Sgp4Track:
    """GCRF states of SGP4 element sets at fixed UTC ``times`` (and, with ``derivatives``, the
    acceleration and jerk :func:`observe` needs, as :class:`Satellite` gives them), the frame
    transformations evaluated once: ``fit-tle`` evaluates many element sets at the same samples."""

    def __init__(self, times, eop=None, derivatives: bool = True):
        t = np.asarray(times, dtype="datetime64[ns]").reshape(-1)
        self.times, self.derivatives = t, derivatives
        step = np.timedelta64(int(FD_STEP_S * 1e9), "ns")
        every = np.concatenate([t - step, t, t + step]) if derivatives else t
        self.jd1, self.jd2 = datetime64_to_jd_utc(every)
        self.maps = teme_to_gcrf_maps(self.jd1, self.jd2, eop)

    def states(self, sat) -> np.ndarray:
        """GCRF ``[r, v]`` (N, 6) of ``sat`` (a :class:`~trackproc.io.tle.Tle` or ``Satrec``) at the times."""
        x = self._all(sat)
        return np.split(x, 3)[1] if self.derivatives else x

    def _all(self, sat) -> np.ndarray:
        r, v = sgp4_teme(sat, self.jd1, self.jd2)
        return np.einsum("nij,nj->ni", self.maps, np.concatenate([r, v], -1))

    def rvaj(self, sat):
        """Position, velocity, acceleration, jerk (each (N, 3), GCRF SI) at the times."""
        if not self.derivatives:
            raise ValueError("this track was built without derivatives")
        return _rvaj_from_states(self._all(sat), FD_STEP_S)


def station_itrf(station, earth: str = "wgs84") -> np.ndarray:
    """ITRF position (m) of a stations-table row (:func:`trackproc.dynamics.geodesy.station_itrf`)."""
    return geodesy.station_itrf(station, earth)[2]


def observe(sat: Satellite, station, t_s, *, carrier_hz: float = 1.0, range_rate_model: str = "doppler",
            earth: str = "wgs84", mode: str = "one-way"):
    """:class:`~trackproc.models.measurements.Observables` of ``station`` at reception times
    ``t0 + t_s`` (the foundation model, DESIGN.md light time; ``mode`` one-way or two-way)."""

    t = np.atleast_1d(np.asarray(t_s, float))
    r, v, a, j = sat.rvaj(t)
    jd1, jd2 = ts.add_seconds_utc(sat.jd0, t)
    st = station_gcrf(station_itrf(station, earth), jd1, jd2, sat.eop)
    return station_observables(r, v, a, j, st, station, carrier_hz=carrier_hz, range_rate_model=range_rate_model,
                               mode=mode)


def station_observables(r, v, a, j, st, station, *, carrier_hz: float = 1.0, range_rate_model: str = "doppler",
                        mode: str = "one-way"):
    """The foundation model's observables of a satellite state (with acceleration and jerk) seen
    from ``station`` whose GCRF track ``st`` (``station_gcrf``) is at the same reception times."""

    try:
        return observables(r, v, a, j, st.r, st.v, st.a, st.gcrf_to_itrf, float(station.lat_deg) * DEG,
                           float(station.lon_deg) * DEG, carrier_hz=carrier_hz, range_rate_model=range_rate_model,
                           mode=mode)
    except ArithmeticError as exc:
        raise ProcessingError(f"measurement prediction failed: {exc}") from None

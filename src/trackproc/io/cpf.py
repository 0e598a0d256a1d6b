"""ILRS Consolidated Prediction Format (CPF, v1 and v2) ephemerides as a reference orbit.

Records read (ILRS CPF v1.01 / v2.00; record types case-insensitive):

- ``H1 CPF version source year month day hour sequence target``: version 1 or 2;
- ``H2 ILRS-id SIC NORAD start(y m d h m s) end(y m d h m s) step compat target-type ref-frame
  rot-type com-corr``: reference frame 0 (geocentric true body-fixed, i.e. ITRF) is read,
  others refused; the centre-of-mass correction flag (1: positions are of the reflector, not
  the centre of mass) is reported;
- ``10 direction MJD sod leap x y z``: positions (m) at UTC ``MJD + sod``; direction 0
  (instantaneous) and 1 (transmit) are taken as the instant, 2 (receive) likewise — a
  prediction gives one position per epoch; a leap-second flag is kept out (no effect on UTC
  labels).

:func:`cpf_gcrf` turns the ITRF positions into GCRF through :mod:`trackproc.dynamics.frames`
(IAU 2006/2000A with the given Earth orientation).
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np

from trackproc.errors import InputError
from trackproc.io.atomic import is_stdio, read_input_bytes
from trackproc.io.tabular import decode_text
from trackproc.io.validate import MAX_SPAN_S, ORBIT_RADIUS_RANGE_M
from trackproc.dynamics import frames, timescales as ts


@dataclass(frozen=True)
class CpfEphemeris:
    """``times`` (N,) UTC datetime64[ns], ``r_itrf`` (N, 3) m, ``target``, ``source``, ``com_corrected``."""

    times: np.ndarray
    r_itrf: np.ndarray
    target: str
    source: str
    com_corrected: bool = False


def looks_like_cpf(head: str) -> bool:
    for line in head.splitlines():
        fields = line.split()
        if fields:
            return len(fields) >= 2 and fields[0].upper() == "H1" and fields[1].upper() == "CPF"
    return False


def parse_cpf(data: bytes, source: str) -> CpfEphemeris:
    """Parse a CPF file's position records (see the module docstring)."""
    text = decode_text(data, source)
    version, target, com = None, "", False
    mjd, sod, xyz, rows = [], [], [], []
    for row, line in enumerate(text.splitlines(), start=1):
        f = line.split()
        if not f:
            continue
        rec = f[0].upper()
        if rec == "H1":
            if len(f) < 3 or f[1].upper() != "CPF" or f[2] not in ("1", "2"):
                raise InputError("not a CPF v1/v2 header", file=source, row=row, column="H1", found=line.strip(),
                                 expected="H1 CPF 1|2 ...")
            version = int(f[2])
            target = f[-1] if len(f) > 9 else ""
        elif rec == "H2":
            if len(f) >= 22:
                frame, com = f[19], f[21] == "1"
                if frame != "0":
                    raise InputError("unsupported CPF reference frame", file=source, row=row, column="reference frame",
                                     found=frame, expected="0 (geocentric body-fixed, ITRF)")
        elif rec == "10":
            if version is None:
                raise InputError("record 10 before the H1 header", file=source, row=row, found=f[0],
                                 expected="H1 CPF ... first")
            try:
                m, s = int(f[2]), float(f[3])
                p = [float(v) for v in f[5:8]]
            except (IndexError, ValueError):
                raise InputError("invalid CPF position record", file=source, row=row, column="10",
                                 found=line.strip(), expected="10 direction MJD seconds leap x y z") from None
            if not all(math.isfinite(v) for v in p + [s]):
                raise InputError("invalid CPF position record", file=source, row=row, column="10",
                                 found=line.strip(), expected="finite numbers")
            radius = math.sqrt(sum(v * v for v in p))
            if not ORBIT_RADIUS_RANGE_M[0] <= radius <= ORBIT_RADIUS_RANGE_M[1]:
                raise InputError(f"implausible CPF position: |r| = {radius:.6g} m", file=source, row=row,
                                 column="10 (x y z)", found=line.strip(),
                                 expected=f"a geocentric position in metres, |r| between {ORBIT_RADIUS_RANGE_M[0]:g} "
                                          f"and {ORBIT_RADIUS_RANGE_M[1]:g} m (kilometres given?)")
            mjd.append(m)
            sod.append(s)
            xyz.append(p)
            rows.append(row)
    if version is None:
        raise InputError("not a CPF file", file=source, row=1, found="no H1 CPF header", expected="an ILRS CPF file")
    if not xyz:
        raise InputError("no CPF position records", file=source, row=1, found="no 10 records",
                         expected="10 direction MJD seconds leap x y z")
    base = np.datetime64("1858-11-17T00:00:00", "ns")
    times = (base + np.array(mjd, dtype=np.int64) * np.timedelta64(86400 * 10**9, "ns")
             + np.round(np.array(sod) * 1e9).astype(np.int64) * np.timedelta64(1, "ns"))
    order = np.argsort(times, kind="stable")
    return CpfEphemeris(times=times[order], r_itrf=np.array(xyz, float)[order], target=target, source=source,
                        com_corrected=com)


def check_reference(eph: CpfEphemeris, epoch, *, column: str = "--compare") -> None:
    """A CPF as the reference of an orbit from ``epoch``: at least two positions (a distance at
    one instant says nothing about an orbit) and every epoch within the propagation bound
    (:data:`~trackproc.io.validate.MAX_SPAN_S`, 400 days) of the state's epoch."""
    if len(eph.times) < 2:
        raise InputError("a single CPF position cannot check an orbit", file=eph.source, column=column,
                         found=f"{len(eph.times)} position record", expected="two or more 10 records")
    epoch = np.datetime64(epoch, "ns")
    far = max(abs((eph.times[0] - epoch) / np.timedelta64(1, "s")), abs((eph.times[-1] - epoch) / np.timedelta64(1, "s")))
    if far > MAX_SPAN_S:
        raise InputError("the CPF lies too far from the state's epoch", file=eph.source, column=column,
                         found=f"{far / 86400:.1f} days from {str(epoch.astype('datetime64[s]'))}Z",
                         expected=f"CPF epochs within {MAX_SPAN_S / 86400:g} days of the state (the propagation bound)")


def read_cpf(path: str) -> CpfEphemeris:
    """:func:`parse_cpf` of a file (``-``: stdin)."""
    return parse_cpf(read_input_bytes(path), "<stdin>" if is_stdio(path) else str(path))


def cpf_gcrf(eph: CpfEphemeris, eop=None) -> np.ndarray:
    """The CPF positions in GCRF (N, 3), m."""
    jd1, jd2 = ts.datetime64_to_jd_utc(eph.times)
    r, _ = frames.itrf_to_gcrf(eph.r_itrf, np.zeros_like(eph.r_itrf), jd1, jd2, eop)
    return r

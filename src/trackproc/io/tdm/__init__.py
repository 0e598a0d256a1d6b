"""A small reader for CCSDS Tracking Data Messages in KVN form (CCSDS 503.0-B-2, also B-1).

Only what ``trackproc`` needs is interpreted; everything else is either ignored (metadata
that does not change the values) or counted in ``meta["skipped_keywords"]`` (data keywords we
do not turn into measurements), so nothing is dropped silently.

Layout (503.0-B-2 section 3 and 4): a header (``CCSDS_TDM_VERS`` first, then ``CREATION_DATE``,
``ORIGINATOR``, ``MESSAGE_ID``, ``COMMENT``), then one or more segments, each a metadata block
``META_START`` .. ``META_STOP`` followed by a data block ``DATA_START`` .. ``DATA_STOP`` whose
lines read ``KEYWORD = EPOCH VALUE``. The reader is lenient where files in the wild differ:
TABs and runs of blanks, any spacing around ``=``, blank lines, ``COMMENT`` lines anywhere,
lower-case keywords, epochs ``YYYY-MM-DDThh:mm:ss[.s...][Z]`` or day-of-year
``YYYY-DDDThh:mm:ss[.s...][Z]``, CRLF line ends, a UTF-8 byte-order mark.

Conventions (each is also written where it is applied):

* **Time.** ``TIME_SYSTEM`` UTC is used as is; TAI, GPS (= TAI - 19 s) and TT (= TAI + 32.184 s;
  the old name TDT is accepted) are converted to UTC with ERFA's leap-second table
  (``erfa.dat``); any other time system is an error. ``TIMETAG_REF = TRANSMIT`` is an error
  (trackproc time-tags at reception; moving the tag needs the light time, i.e. the orbit).
* **Station.** The path's first entry is the transmitter (503.0-B-2 3.3.2, ``PATH``), so the
  last one is the receiver, where RANGE, DOPPLER_*, RECEIVE_FREQ and ANGLE are measured.
  Rule: for a round-trip path ``i,j,i`` the station is participant ``i``; for a one-way path
  ``i,j`` the station is the receiver ``j`` (a down-link ``2,1`` gives PARTICIPANT_1, the usual
  ground station). Without ``PATH`` (angle-only data, e.g. optical) the station is
  PARTICIPANT_1, the usual convention. Relay / three-way paths (``1,2,3,2,1``, ``1,2,3``) and
  ``MODE = SINGLE_DIFF`` are refused for the kinds we read: they are not a station-to-spacecraft
  measurement.
* **RANGE** (``RANGE_UNITS``: km, default; s = light time; RU): km x 1000, s x c. RU are
  refused: CCSDS leaves their definition to an ICD (the DSN's depend on the uplink band and
  the ramped uplink frequency) and they are ambiguous modulo ``RANGE_MODULUS``, which needs an
  a-priori orbit to resolve; convert them to km or s upstream. A two-way path (three entries)
  is by default taken as already written as the one-way equivalent
  (``two_way_range="one-way-equivalent"``): the spec's own annex examples are written that
  way (a GSOC 1,2,1 example gives 40,016 km at 1.3 deg elevation, a one-way GEO slant
  range). Producers that write the full round trip need ``two_way_range="round-trip"``
  (``trackproc ingest --tdm-two-way-range round-trip``), which halves the values;
  ``meta["range_two_way_halved"]`` records which was done, and a warning names the assumption.
  ``RANGE_MODULUS`` is not applied (recorded in the warnings). A file whose ranges are all
  of one path and that has no Doppler data takes that path's link mode as its ``doppler_mode``
  (the link mode estimate models ranges with); ranges of another path than the file's
  Doppler data are named in a warning (split such a file by path).
* **DOPPLER_INSTANTANEOUS / DOPPLER_INTEGRATED** are range rates in km/s (503.0-B-2 keyword
  tables; "instantaneous range rate", "mean range rate over INTEGRATION_INTERVAL"), i.e. the
  time derivative of the range: positive when the range increases (receding), which is
  trackproc's convention, so the value is only scaled (x 1000), never negated. They are not
  halved on two-way paths (a range rate, not a round-trip count). DOPPLER_INTEGRATED (and
  RECEIVE_FREQ_n, a counted frequency) is re-tagged to the middle of its integration
  interval: ``INTEGRATION_REF`` START -> +interval/2, END -> -interval/2, MIDDLE -> 0.
* **RECEIVE_FREQ_n** (Hz; ``FREQ_OFFSET`` is added to every RECEIVE_FREQ to reconstruct it)
  becomes kind ``doppler`` = received - nominal. The nominal is the transmitter's
  ``TRANSMIT_FREQ_n`` data (n = the first participant of PATH, as in the spec's annex
  examples), with ``TRANSMIT_FREQ_RATE_n`` ramps integrated, evaluated at the receive time tag
  (the light time is ignored: error = ramp rate x light time), times
  ``TURNAROUND_NUMERATOR/TURNAROUND_DENOMINATOR`` on a two-way path. Without TRANSMIT_FREQ the
  ``carrier_hz`` argument is the nominal carrier of the *received* signal; with neither the
  file is refused (pass ``--carrier-hz``). A received frequency more than 0.1 % away from its
  nominal is refused (a missing turnaround ratio, FREQ_OFFSET or wrong carrier).
* **ANGLE_1 / ANGLE_2** with ``ANGLE_TYPE = AZEL`` are azimuth / elevation in degrees; output in
  radians, azimuth wrapped into [0, 2 pi) (the TDM allows [-180, 360)). Other angle types
  (RADEC, XEYN, XSYE) are refused, naming the ANGLE_TYPE.
* **CORRECTION_*.** When ``CORRECTIONS_APPLIED = NO`` the corrections we can place
  (CORRECTION_RANGE in range units, CORRECTION_DOPPLER km/s, CORRECTION_ANGLE_1/2 deg,
  CORRECTION_RECEIVE / CORRECTION_TRANSMIT Hz) are added to the raw values ("has been added or
  should be added"); when YES they are already in the data; a non-zero correction without
  CORRECTIONS_APPLIED is refused as ambiguous.
* **TRANSMIT_DELAY_n / RECEIVE_DELAY_n** are not applied (the standard does not say whether
  the data already include them); non-zero values are listed in ``meta["warnings"]``, as are
  ``DATA_QUALITY = DEGRADED`` segments and a DOPPLER_INTEGRATED without INTEGRATION_REF.
* **sigma** is NaN: the TDM has no per-sample uncertainty keyword.

Errors are :class:`~trackproc.errors.InputError` naming the file (``source``), the 1-based line
and the keyword (column).
"""

from __future__ import annotations

from trackproc.errors import InputError
from trackproc.io.raw import RawMeasurements
from trackproc.io.validate import check_carrier
from trackproc.io.tdm.convert import Converter
from trackproc.io.tdm.kvn import Parser

__all__ = ["read_tdm"]


def read_tdm(data: bytes, source: str, *, carrier_hz: float | None = None,
             two_way_range: str = "one-way-equivalent") -> RawMeasurements:
    """Read a CCSDS TDM in KVN form into :class:`RawMeasurements` (SI units, UTC).

    ``data`` is the whole file, ``source`` its name for messages. ``carrier_hz`` is the nominal
    carrier of the received signal, used for ``RECEIVE_FREQ_n`` when the segment gives no
    ``TRANSMIT_FREQ_n``. ``two_way_range`` says how the file writes RANGE on a two-way path:
    ``"round-trip"`` (halved here to the one-way equivalent) or ``"one-way-equivalent"``.
    See the module docstring for every convention.
    """
    if carrier_hz is not None:
        # read before ingest checks its options (a reader's error comes first): the same check here
        check_carrier(carrier_hz)
    if two_way_range not in ("round-trip", "one-way-equivalent"):
        raise InputError("unknown two-way range convention", found=two_way_range,
                         expected="'round-trip' or 'one-way-equivalent'")
    parser = Parser(source)
    header, segments = parser.parse(data)
    return Converter(source, header, segments, parser.skipped, carrier_hz,
                      two_way_range == "round-trip").run()

"""Which range samples take which corrections (pipeline.range_corrections): CRD sessions in auto
mode, every range with mendes-pavlis (a wavelength required), already-corrected sessions, the
centre-of-mass offset; each sample corrected once."""

import numpy as np
import pandas as pd
import pytest

from trackproc.errors import InputError
from trackproc.io.passfile import PassTable
from trackproc.io.stations import Station
from trackproc.models import troposphere as tp
from trackproc.pipeline.range_corrections import range_correction_modifiers

EPOCH = np.datetime64("2016-02-13T00:00:00", "ns")
STATIONS = {"7090": Station("7090", -29.05, 115.35, 244.5), "RAD": Station("RAD", 40.0, 116.0, 50.0)}


def _frame(times, station, kind="range", source="f"):
    return pd.DataFrame({"time": pd.to_datetime(times, utc=True), "station": station, "kind": kind,
                         "_source": source})


def _crd_meta(applied=False, wavelength=532.0):
    return {"inputs": {"x.npt": {"crd": {
        "sessions": [{"station": "7090", "start": "2016-02-13T01:00:00Z", "end": "2016-02-13T01:20:00Z",
                      "wavelength_nm": wavelength, "troposphere_applied": applied},
                     {"station": "7090", "start": "2016-02-13T01:25:00Z", "end": "2016-02-13T01:40:00Z",
                      "wavelength_nm": wavelength, "troposphere_applied": applied}],
        "meteo": {"7090": {"time": ["2016-02-13T01:00:00Z"], "pressure_hpa": [980.0], "temperature_k": [300.0],
                           "humidity_percent": [30.0]}}}}}}


def _rows(mods, frame):
    from trackproc.models.observation import MeasurementSet

    n = len(frame)
    t_s = ((frame["time"].dt.tz_localize(None) - pd.Timestamp(EPOCH)).dt.total_seconds()).to_numpy()
    meas = MeasurementSet(t_s=t_s, kind=frame["kind"].to_numpy(), station=frame["station"].to_numpy(),
                          pass_id=np.full(n, "p"), observed=np.zeros(n), sigma=np.ones(n), r_st=np.zeros((n, 3)),
                          v_st=np.zeros((n, 3)))
    return [(type(m).__name__, m.rows(meas).tolist()) for m in mods]


def test_auto_corrects_crd_sessions_once_and_nothing_else():
    frame = _frame(["2016-02-13T01:10:00", "2016-02-13T01:30:00", "2016-02-13T01:10:00"], ["7090", "7090", "RAD"])
    tables = [("f", PassTable(frame, _crd_meta()))]
    mods = range_correction_modifiers(frame, tables, STATIONS, EPOCH)
    rows = _rows(mods, frame)
    # the two sessions (1 h margins) overlap: merged, each sample once; the radar range untouched
    # and the solid-Earth tides of every station (auto: on with CRD data)
    assert rows == [("SolidTideDisplacement", [0, 1, 2]), ("TroposphereDelay", [0, 1])]
    assert mods[1].meteo is not None                        # the CRD meteo, not the standard atmosphere
    off = range_correction_modifiers(frame, tables, STATIONS, EPOCH, solid_tides=False)
    assert _rows(off, frame) == [("TroposphereDelay", [0, 1])]


def test_already_applied_sessions_and_the_centre_of_mass_offset():
    frame = _frame(["2016-02-13T01:10:00"], ["7090"])
    tables = [("f", PassTable(frame, _crd_meta(applied=True)))]
    mods = range_correction_modifiers(frame, tables, STATIONS, EPOCH, com_offset_m=0.251, solid_tides=False)
    assert _rows(mods, frame) == [("CentreOfMassOffset", [0])]
    with pytest.raises(InputError, match="already applied"):
        range_correction_modifiers(frame, tables, STATIONS, EPOCH, troposphere="mendes-pavlis")


def test_mendes_pavlis_on_any_range_needs_a_wavelength():
    frame = _frame(["2016-02-13T01:10:00", "2016-02-13T01:10:00"], ["RAD", "RAD"], kind=["range", "doppler"])
    tables = [("f", PassTable(frame, {}))]
    with pytest.raises(InputError, match="wavelength") as err:
        range_correction_modifiers(frame, tables, STATIONS, EPOCH, troposphere="mendes-pavlis")
    assert "--wavelength-nm" in str(err.value)
    mods = range_correction_modifiers(frame, tables, STATIONS, EPOCH, troposphere="mendes-pavlis", wavelength_nm=1064)
    assert _rows(mods, frame) == [("TroposphereDelay", [0])]
    assert mods[0].meteo is None and mods[0].wavelength_um == pytest.approx(1.064)
    assert range_correction_modifiers(frame, tables, STATIONS, EPOCH) == []        # auto: not a laser range
    with pytest.raises(InputError, match="optical"):
        range_correction_modifiers(frame, tables, STATIONS, EPOCH, troposphere="mendes-pavlis", wavelength_nm=2e6)
    with pytest.raises(InputError, match="unknown troposphere"):
        range_correction_modifiers(frame, tables, STATIONS, EPOCH, troposphere="saastamoinen")

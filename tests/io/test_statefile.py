"""State files (JSON) and TLEs: round trips, validation errors naming the field, frames."""

import json

import numpy as np
import pytest

from trackproc.constants import force_model_constants
from trackproc.dynamics import frames
from trackproc.dynamics import timescales as ts
from trackproc.errors import InputError
from trackproc.io import statefile as sf
from trackproc.io import tle as tl

DESIGN_EXAMPLE = {
    "epoch": "2026-03-20T09:30:00.000Z", "frame": "GCRF",
    "position_m": [3774841.0, -1538034.0, 5924146.0], "velocity_m_s": [-4816.6, 3936.4, 4091.1],
}
ISS = ("ISS (ZARYA)\n"
       "1 25544U 98067A   19343.69339541  .00001764  00000-0  38792-4 0  9991\n"
       "2 25544  51.6439 211.2001 0007417  17.6667  85.6398 15.50103472202482\n")


def doc(**changes):
    d = dict(DESIGN_EXAMPLE)
    for k, v in changes.items():
        if v is None:
            d.pop(k, None)
        else:
            d[k] = v
    return json.dumps(d)


def full_state():
    a = np.random.default_rng(5).normal(size=(7, 7))
    scale = np.sqrt(np.r_[[100.0] * 3, [1e-4] * 3, [4.0]])
    cov = (a * scale[:, None]) @ (a * scale[:, None]).T
    params = list(sf.STATE_PARAMETERS) + ["range_bias:ZHY"]
    s = sf.State.from_vectors("2026-03-20T09:30:00.123456789Z", DESIGN_EXAMPLE["position_m"],
                              DESIGN_EXAMPLE["velocity_m_s"], parameters=params,
                              values=np.r_[DESIGN_EXAMPLE["position_m"], DESIGN_EXAMPLE["velocity_m_s"], 12.5],
                              covariance=cov, force_model="j2",
                              diagnostics={"iterations": 6, "rms": {"ZHY": {"range": 1.2}}, "converged": True},
                              extra={"note": "kept"})
    return s


def test_design_example_reads():
    s = sf.parse_state(doc(), "state.json")
    assert s.epoch == np.datetime64("2026-03-20T09:30:00", "ns")
    assert s.r_m.tolist() == DESIGN_EXAMPLE["position_m"] and s.v_m_s.tolist() == DESIGN_EXAMPLE["velocity_m_s"]
    assert s.parameters == list(sf.STATE_PARAMETERS) and s.covariance is None
    j1, j2 = ts.datetime64_to_jd_utc(s.epoch)
    assert s.jd_utc == (float(j1), float(j2))


def test_write_read_round_trip_is_exact_and_deterministic(tmp_path):
    s = full_state()
    path = tmp_path / "s.json"
    sf.write_state(s, str(path), eop_source="constant UT1-UTC = 0.1 s")
    text = path.read_text()
    back = sf.read_state(str(path))
    assert back.epoch == s.epoch
    assert np.array_equal(back.r_m, s.r_m) and np.array_equal(back.v_m_s, s.v_m_s)
    assert np.array_equal(back.covariance, s.covariance) and np.array_equal(back.values, s.values)
    assert back.parameters == s.parameters and back.force_model == "j2"
    assert back.diagnostics == s.diagnostics and back.extra == {"note": "kept"}
    assert back.eop_source == "constant UT1-UTC = 0.1 s"
    loaded = json.loads(text)
    assert loaded["frame"] == "GCRF" and loaded["force_model"] == "two-body+J2"
    assert loaded["constants"] == force_model_constants("j2")
    assert loaded["epoch"] == "2026-03-20T09:30:00.123456789Z"
    assert np.allclose(loaded["sigma"], np.sqrt(np.diag(s.covariance)), rtol=1e-15)
    sf.write_state(back, str(tmp_path / "again.json"))
    assert (tmp_path / "again.json").read_text() == text


def test_state_covariance_block():
    s = full_state()
    assert s.state_covariance.shape == (6, 6)
    assert np.array_equal(s.state_covariance, s.covariance[:6, :6])


@pytest.mark.parametrize("field", ["epoch", "frame", "position_m", "velocity_m_s"])
def test_missing_field_is_named(field):
    with pytest.raises(InputError) as err:
        sf.parse_state(doc(**{field: None}), "bad.json")
    assert err.value.column == field and err.value.file == "bad.json"
    assert "missing field" in str(err.value)


@pytest.mark.parametrize("field, value, words", [
    ("epoch", "yesterday", "invalid epoch"),
    ("epoch", "2026-13-40T00:00:00Z", "invalid epoch"),
    ("epoch", 12, "invalid epoch"),
    ("frame", "B1950", "unknown frame"),
    ("frame", 3, "wrong type"),
    ("position_m", [1.0, 2.0], "wrong type or length"),
    ("position_m", ["a", "b", "c"], "wrong type or length"),
    ("velocity_m_s", "fast", "wrong type or length"),
    ("position_m", [3774.841, -1538.034, 5924.146], "kilometres given"),
    ("parameters", ["x", "x"], "duplicate parameter"),
    ("force_model", 2, "wrong type"),
    ("diagnostics", [1], "wrong type"),
])
def test_ill_typed_field_is_named(field, value, words):
    with pytest.raises(InputError) as err:
        sf.parse_state(doc(**{field: value}), "bad.json")
    assert err.value.column == field
    assert words in str(err.value)


def test_covariance_checks():
    base = dict(DESIGN_EXAMPLE, parameters=list(sf.STATE_PARAMETERS))
    good = np.diag([1.0, 1, 1, 1e-6, 1e-6, 1e-6])

    def parse(**extra):
        return sf.parse_state(json.dumps(dict(base, **extra)), "c.json")

    assert parse(covariance=good.tolist()).covariance.shape == (6, 6)
    for bad, words in [(good[:5, :5], "shape"),
                       ([[1.0] * 6] * 5 + [[1.0] * 5], "shape"),
                       (np.where(np.eye(6, k=1) > 0, 0.5, good), "not symmetric"),
                       (np.diag([1.0, 1, 1, 1, 1, -1]), "negative variance"),
                       (np.ones((6, 6)) + np.diag([0, 0, 0, 0, 0, -0.5]), "not positive semi-definite")]:
        with pytest.raises(InputError) as err:
            parse(covariance=np.asarray(bad).tolist() if not isinstance(bad, list) else bad)
        assert err.value.column == "covariance" and words in str(err.value)
    with pytest.raises(InputError, match="sigma disagrees"):
        parse(covariance=good.tolist(), sigma=[2.0, 1, 1, 1e-3, 1e-3, 1e-3])
    with pytest.raises(InputError) as err:
        parse(values=[1.0] * 5)
    assert err.value.column == "values"
    with pytest.raises(InputError, match="disagree"):
        parse(values=[0.0] * 6)
    # positive semi-definite (singular) is accepted
    singular = np.ones((6, 6))
    assert parse(covariance=singular.tolist()).covariance is not None


def test_values_without_parameters_default_to_the_state():
    s = sf.parse_state(doc(sigma=[1.0, 1, 1, 0.1, 0.1, 0.1]), "s.json")
    assert s.parameters == list(sf.STATE_PARAMETERS) and s.sigma[3] == 0.1


def test_epoch_offsets_are_converted_to_utc():
    assert sf.parse_epoch("2026-03-20T11:30:00+02:00") == np.datetime64("2026-03-20T09:30:00", "ns")
    assert sf.parse_epoch("2026-03-20T09:30:00") == np.datetime64("2026-03-20T09:30:00", "ns")
    with pytest.raises(InputError, match="leap-second"):
        sf.parse_epoch("2016-12-31T23:59:60Z")
    assert sf.format_epoch(np.datetime64("2026-03-20T09:30:00.5")) == "2026-03-20T09:30:00.500Z"


def test_eme2000_state_and_covariance_are_rotated_to_gcrf():
    cov = np.diag([100.0, 400.0, 900.0, 1e-2, 4e-2, 9e-2])
    s = sf.parse_state(doc(frame="J2000", parameters=list(sf.STATE_PARAMETERS), covariance=cov.tolist()), "s.json")
    r, v = frames.eme2000_to_gcrf(DESIGN_EXAMPLE["position_m"], DESIGN_EXAMPLE["velocity_m_s"])
    assert np.allclose(s.r_m, r[0], rtol=0, atol=1e-8) and np.allclose(s.v_m_s, v[0], rtol=0, atol=1e-11)
    rb = frames.frame_bias_matrix()
    assert np.allclose(s.covariance[:3, :3], rb.T @ cov[:3, :3] @ rb, rtol=1e-12, atol=1e-12)
    assert np.trace(s.covariance[:3, :3]) == pytest.approx(1400.0, rel=1e-12)
    assert s.extra["converted_from_frame"] == "EME2000"
    assert 0.1 < np.linalg.norm(s.r_m - np.array(DESIGN_EXAMPLE["position_m"])) < 2.0   # ~23 mas at 7000 km


def test_itrf_state_converted_with_the_earth_orientation():
    eop = ts.EarthOrientation.constant(0.2)
    s = sf.parse_state(doc(frame="ITRF"), "s.json", eop)
    r, v = frames.itrf_to_gcrf(DESIGN_EXAMPLE["position_m"], DESIGN_EXAMPLE["velocity_m_s"], *s.jd_utc, eop)
    assert np.allclose(s.r_m, r[0], rtol=0, atol=1e-8) and np.allclose(s.v_m_s, v[0], rtol=0, atol=1e-11)
    # and the state written back is GCRF and reads back unchanged
    back = sf.parse_state(sf.state_json(s), "again.json")
    assert np.array_equal(back.r_m, s.r_m)


def test_not_json_is_an_input_error():
    with pytest.raises(InputError, match="not valid JSON") as err:
        sf.parse_state("{epoch: 1", "x.json")
    assert err.value.file == "x.json"
    with pytest.raises(InputError, match="JSON object"):
        sf.parse_state("[1, 2]", "x.json")
    with pytest.raises(InputError, match="file not found"):
        sf.read_state("/no/such/state.json")


# ------------------------------------------------------------------------- TLE

def test_tle_three_lines_epoch_and_sgp4_state():
    t = tl.parse_tle(ISS, "iss.tle")
    assert t.name == "ISS (ZARYA)" and t.satnum == "25544"
    epoch = tl.tle_epoch(t)
    assert abs(epoch - np.datetime64("2019-12-09T16:38:29.363424", "ns")) < np.timedelta64(1, "ms")
    s = tl.tle_state(t)
    assert s.epoch == epoch
    j1, j2 = ts.datetime64_to_jd_utc(epoch)
    r_teme, v_teme = tl.sgp4_teme(t, j1, j2)
    r, v = frames.teme_to_gcrf(r_teme, v_teme, j1, j2)
    assert np.allclose(s.r_m, r[0], atol=1e-6) and np.allclose(s.v_m_s, v[0], atol=1e-9)
    assert 6.6e6 < np.linalg.norm(s.r_m) < 6.9e6 and 7.5e3 < np.linalg.norm(s.v_m_s) < 7.8e3
    later = tl.tle_state(t, at="2019-12-09T17:00:00Z")
    assert later.epoch == np.datetime64("2019-12-09T17:00:00", "ns")
    assert s.extra["tle"][0].startswith("1 25544")


def test_tle_two_lines_and_state_or_tle(tmp_path):
    path = tmp_path / "iss.tle"
    path.write_text("\n".join(ISS.splitlines()[1:]) + "\n")
    s = sf.read_state_or_tle(str(path))
    assert s.force_model == "sgp4"
    path2 = tmp_path / "s.json"
    path2.write_text(doc())
    assert sf.read_state_or_tle(str(path2)).r_m[0] == 3774841.0


def test_tle_checksum_error_names_row_and_column():
    bad = ISS.replace("0  9991", "0  9995")
    with pytest.raises(InputError) as err:
        tl.parse_tle(bad, "iss.tle")
    assert err.value.row == 2 and "checksum" in err.value.column
    assert "found 5" in str(err.value) and "expected 1" in str(err.value)


@pytest.mark.parametrize("mutate, words", [
    (lambda lines: lines[:2], "not a TLE"),
    (lambda lines: [lines[0], lines[1][:-1], lines[2]], "length"),
    (lambda lines: [lines[0], "3" + lines[1][1:], lines[2]], "element line"),
    (lambda lines: [lines[0], lines[1], lines[2][:2] + "25545" + lines[2][7:-1] + "3"], "different satellites"),
])
def test_tle_shape_errors(mutate, words):
    lines = ISS.splitlines()
    with pytest.raises(InputError, match=words):
        tl.parse_tle("\n".join(mutate(lines)), "x.tle")


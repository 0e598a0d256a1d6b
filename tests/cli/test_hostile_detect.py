"""Hostile class: detect must not decide from samples outside the nominal flight (issue 14: 3-D
detect decided from samples a day before the flight; a nominal a day after the pass crashed)."""

from __future__ import annotations

import json

import pytest

from hostile import assert_rejected

NOMINAL = {"impact_time": "2026-03-20T10:00:00Z", "velocity_kms": 3, "angle_deg": 48, "station": "KIR",
           "tau_s": 30}
ST = "station,lat_deg,lon_deg,height_m\nKIR,67.8,20.9,400\n"


@pytest.fixture(scope="module")
def passes(tmp_path_factory):
    """A planar and a 3-D ballistic pass simulated for NOMINAL (one each)."""
    from trackproc.cli import app as cli_app

    folder = tmp_path_factory.mktemp("detect")
    (folder / "st.csv").write_text(ST)
    out = {}
    for model in ("planar", "3d"):
        doc = dict(NOMINAL, model=model, **({"direction": "against"} if model == "3d" else {}))
        (folder / f"{model}.json").write_text(json.dumps(doc))
        path = folder / f"{model}.parquet"
        code = cli_app.main(["simulate", "--ballistic", str(folder / f"{model}.json"), "--stations",
                             str(folder / "st.csv"), "--step", "4", "--elevation-mask-deg", "0", "--dut1", "0",
                             "--sigma-angle-deg", "0.2", "--seed", "5", "-q", "-o", str(path)])
        assert code == 0
        out[model] = (path, doc)
    return out


@pytest.mark.parametrize("model", ["planar", "3d"])
@pytest.mark.parametrize("impact", ["2026-03-19T10:00:00Z",      # the pass lies a day after the impact
                                    "2026-03-21T10:00:00Z",      # the pass lies a day before the flight
                                    "2026-03-20T11:00:00Z"])     # an hour: still before launch
def test_samples_outside_the_flight(run_cli, write, passes, model, impact):
    path, doc = passes[model]
    nominal = write("n.json", json.dumps(dict(doc, impact_time=impact)))
    result = run_cli(["detect", path, "--nominal", nominal, "--dut1", "0", "-q"])
    assert_rejected(result, 2, path.name, "time")


@pytest.mark.parametrize("model", ["planar", "3d"])
def test_the_matching_nominal_still_decides(run_cli, write, passes, model):
    path, doc = passes[model]
    nominal = write("n.json", json.dumps(doc))
    result = run_cli(["detect", path, "--nominal", nominal, "--dut1", "0", "-q"])
    assert result.exit_code == 0, result.stderr
    assert json.loads(result.stdout)["decision"] in ("H0", "H1")

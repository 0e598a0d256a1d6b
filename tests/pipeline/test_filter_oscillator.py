"""``trackproc filter`` with the transmitter's frequency offset as a process, on simulated one-way
VHF Doppler (DopTrack-like: 145.9 MHz, 1.5 Hz white noise, 1 s samples, one 55 deg pass of the
seed 004 Table 1 orbit): the offset wanders as a random walk (``--oscillator-noise``) or a
first-order Gauss–Markov process (``--bias-gm doppler_offset=SIGMA,TAU``), drawn in the test.

Independent reference: the truth of the simulation, the offset path drawn here (a Wiener process
of the stated intensity; an exact discrete Gauss–Markov sequence, Gelb 1974 table 3.3-1). With the
process given to the filter, the filtered and smoothed offset are within 4 of their sigmas of the
drawn path at every sample, and the normalised innovations squared per sample is about 1 (χ²);
with the offset held constant, the same data are not (the check can fail)."""

from __future__ import annotations

from functools import lru_cache

import numpy as np
import pytest

from trackproc.io.passfile import PassTable
from trackproc.io.statefile import State
from trackproc.pipeline.estimate import EstimateOptions
from trackproc.pipeline.filter import FilterOptions, filter_passes
from trackproc.pipeline.refine import traverse_station
from trackproc.pipeline.simulate import SimulateOptions, simulate

from test_refine import EOP, TRUTH

#: VHF as DopTrack's Delfi-C3: carrier (Hz), white noise (Hz)
CARRIER_HZ, SIGMA_HZ = 145.9e6, 1.5
#: the random walk of the offset (Hz/sqrt(s)): ~5 Hz over the pass
WALK = 0.2
#: the Gauss–Markov offset: steady-state sigma (Hz), time constant (s)
GM_SIGMA, GM_TAU = 5.0, 300.0


@lru_cache(maxsize=None)
def _clean():
    station, _ = traverse_station(TRUTH, cross_track_m=500e3, eop=EOP)
    sim = simulate(TRUTH, {station.name: station},
                   SimulateOptions(duration_s=1800, step_s=1.0, start=np.datetime64("2026-03-20T09:15:00"),
                                   carrier_hz=CARRIER_HZ, seed=4, kinds=("doppler",), mode="one-way",
                                   sigma_doppler_hz=SIGMA_HZ, freq_offset_hz=0.0, freq_drift_hz_s=0.0), EOP)
    return station, sim


def wandering(process: str, seed: int = 7):
    """The pass with the offset path of ``process`` added: ``(PassTable, station, t_s, path Hz)``."""
    station, sim = _clean()
    frame = sim.frame.copy()
    t = (frame["time"].dt.tz_localize(None) - frame["time"].dt.tz_localize(None).min()).dt.total_seconds().to_numpy()
    rng = np.random.default_rng(seed)
    dt = np.diff(t, prepend=t[0])
    if process == "walk":
        path = 150.0 + np.cumsum(WALK * np.sqrt(dt) * rng.standard_normal(t.size))
    else:
        e = np.exp(-dt / GM_TAU)
        w = GM_SIGMA * np.sqrt(1.0 - e * e) * rng.standard_normal(t.size)
        path = np.empty(t.size)
        path[0] = GM_SIGMA * rng.standard_normal()
        for i in range(1, t.size):
            path[i] = e[i] * path[i - 1] + w[i]
    frame["value"] = frame["value"].to_numpy() + path
    return PassTable(frame, sim.meta), station, t, path


def run(process: str, given: bool, smooth: bool = False):
    table, station, t, path = wandering(process)
    initial = State.from_vectors(TRUTH.epoch, TRUTH.r_m, TRUTH.v_m_s,
                                 covariance=np.diag([100.0 ** 2] * 3 + [0.1 ** 2] * 3))
    eo = EstimateOptions(doppler_bias="offset", apriori_initial=True, noise="white", kinds=["doppler"])
    fo = FilterOptions(problem=eo, edit_sigma=None, smooth=smooth,
                       bias_walk={"doppler_offset": WALK} if given and process == "walk" else {},
                       bias_gm={"doppler_offset": (GM_SIGMA, GM_TAU)} if given and process == "gm" else {})
    res = filter_passes([("sim", table)], initial, {station.name: station}, fo, EOP)
    sw = res.sweep
    i = [n.startswith("doppler_offset") for n in res.problem.names].index(True)
    which = "s" if smooth else "f"
    est = getattr(sw, "x_" + which)[sw.step, i] * sw.scales[i]
    sig = np.sqrt(getattr(sw, "p_" + which)[sw.step, i, i]) * sw.scales[i]
    # the problem's samples are in the pass's time order: the path drawn per sample
    order = np.argsort(res.problem.meas.t_s, kind="stable")
    z = np.empty(t.size)
    z[order] = (est[order] - path[np.argsort(t, kind="stable")]) / sig[order]
    rec = res.state.extra["filter"]
    return np.abs(z), rec["nis"] / rec["nis_dof"], sig


@pytest.mark.parametrize("process", ["walk", "gm"])
def test_filter_recovers_a_wandering_oscillator_within_its_sigmas(process):
    z_f, nis, sig = run(process, given=True)
    z_s, _, _ = run(process, given=True, smooth=True)
    print(f"{process}: filtered max |z| {z_f.max():.2f}, smoothed {z_s.max():.2f}, NIS per sample {nis:.3f}, "
          f"offset sigma {sig.min():.2f}-{sig.max():.2f} Hz")
    assert z_f.max() <= 4.0 and z_s.max() <= 4.0, (z_f.max(), z_s.max())
    assert 0.85 <= nis <= 1.15, nis
    # the offset held constant cannot follow the path: the same data fall outside
    z_c, nis_c, _ = run(process, given=False)
    print(f"{process}, constant offset: max |z| {z_c.max():.1f}, NIS per sample {nis_c:.2f}")
    assert z_c.max() > 4.0 and nis_c > 1.5, (z_c.max(), nis_c)

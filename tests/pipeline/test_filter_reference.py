"""The filter's reference trajectory restarted where it restarts (a tracking segment, a
relinearisation): each chunk's reference is integrated from its own start over the chunk only.
References: the problem's trajectory integrated once from the epoch (the reference the filter
follows when it never restarts through its own state, to the integrator's tolerance), an
independent round trip through the epoch for a reference restarted through the filter's state,
and the propagated span, which must grow with the arc and not with its square."""

from __future__ import annotations

from functools import lru_cache

import numpy as np
import pytest

from trackproc.dynamics import propagator
from trackproc.dynamics.forces import ForceModel
from trackproc.io.icgem import load_field
from trackproc.io.passfile import PassTable
from trackproc.pipeline.estimate import EstimateOptions, build_problem
from trackproc.pipeline.filter import FilterOptions
from trackproc.pipeline.filter import run as fr
from trackproc.pipeline.simulate import SimulateOptions, simulate

from test_estimate import EOP, STATIONS, TRUTH


@lru_cache(maxsize=None)
def _problem(days: float, force: str = "j2"):
    """Range and range-rate of three stations (J2), every 120 s of visibility over ``days``; the
    filter's model J2, or (``full``) the degree-2 field with the Sun and the Moon."""
    sim = simulate(TRUTH, STATIONS, SimulateOptions(duration_s=days * 86400.0, step_s=120.0, seed=3,
                                                    kinds=("range", "range_rate"), force="j2"), EOP)
    extra = {}
    if force == "full":
        extra = dict(force="full", force_model=ForceModel(field=load_field(degree=2, date=np.datetime64(
            TRUTH.epoch, "s")), third_bodies=("sun", "moon"), relativity=False, eop=EOP))
    eo = EstimateOptions(apriori_sigma={"position": 100.0, "velocity": 0.1}, noise="white",
                         kinds=["range", "range_rate"], **extra)
    return build_problem([("sim.parquet", PassTable(sim.frame, sim.meta))], TRUTH, None, eo, EOP), eo


def _sweep(days: float, restarts: bool, force: str = "j2"):
    pb, eo = _problem(days, force)
    opt = FilterOptions(problem=eo, edit_sigma=None)
    centre, p0 = fr.initial_covariance(pb)
    return pb, fr.sweep(pb, pb.x0, centre, p0, opt, restarts=restarts)


def test_a_reference_never_restarted_through_the_filter_is_the_epochs_trajectory():
    """Without restarts through the filter's state every chunk's reference starts from the previous
    chunk's at their shared step: chained over 3 days of segments it is the one trajectory
    integrated from the epoch (Taylor at 1e-15 per step: millimetres would mean a wrong restart
    time or frame; a restart 1 s off is kilometres)."""
    pb, sw = _sweep(3.0, restarts=False)
    assert len(sw.segments) > 20
    whole = pb.trajectory(pb.x0, cover=sw.t_s)
    scales = sw.scales[:6]
    err = np.abs(sw.z_ref[:, :6] * scales - whole.state(sw.t_s))
    assert err[:, :3].max() < 1e-4 and err[:, 3:].max() < 1e-7, (err[:, :3].max(), err[:, 3:].max())


def test_a_restarted_trajectory_sees_the_absolute_time_of_the_sun_and_the_moon():
    """Problem.trajectory started at t_r (the full model: Sun, Moon, degree-2 field, DOP853) from
    the epoch trajectory's state there follows that trajectory to DOP853's tolerance (3e-4 m over
    20000 s measured), where the same state integrated with the epoch's time instead of its own
    feels the Moon and the tesseral field of hours earlier (2-4 m 600 s on, 100 m and more later)."""
    pb, _ = _problem(2.0, "full")
    t_r = 37200.0
    t = t_r + np.array([600.0, 5000.0, 20000.0])
    whole = pb.trajectory(pb.x0, cover=t)
    x_r = np.concatenate([whole.state(np.array([t_r]))[0], pb.x0[6:]])
    restarted = pb.trajectory(x_r, cover=t, start_s=t_r)
    np.testing.assert_allclose(restarted.stm(np.array([t_r]))[0], np.eye(6), atol=1e-9)
    err = np.linalg.norm(restarted.state(t)[:, :3] - whole.state(t)[:, :3], axis=1)
    assert err.max() < 0.01, err
    wrong = pb.trajectory(x_r, cover=t - t_r)
    assert np.linalg.norm(wrong.state(t - t_r)[0, :3] - whole.state(t)[0, :3]) > 1.0


def test_a_reference_restarted_through_the_filter_matches_its_round_trip_through_the_epoch():
    """Restarted through the filter's state, a chunk's reference starts exactly at that state; the
    same orbit integrated back to the epoch and forward again from there (the former scheme's
    epoch-anchored reference) agrees with it over the chunk (the last segments: converged, no
    relinearisation inside them)."""
    pb, sw = _sweep(2.0, restarts=True)
    starts = [ka for ka, _ in sw.segments[1:]]
    assert len(starts) > 10
    scales = sw.scales[:6]
    worst = 0.0
    for ka in starts[-3:]:
        kb = next(b for a, b in sw.segments if a == ka)
        t_r = sw.t_s[ka - 1]
        # the filtered state at t_r back to the epoch, then the epoch's trajectory over the chunk
        back = propagator.propagate_from(*np.split(sw.x_f[ka - 1, :6] * scales, 2), pb.epoch, t_r, [0.0],
                                         force=pb.force, frame=pb.frame)
        x0 = back.state(np.array([0.0]))[0]
        fwd = propagator.propagate(x0[:3], x0[3:], pb.epoch, [sw.t_s[kb] + 1.0], force=pb.force, frame=pb.frame)
        t = sw.t_s[ka:kb + 1]
        worst = max(worst, float(np.abs(sw.z_ref[ka:kb + 1, :3] * scales[:3] - fwd.state(t)[:, :3]).max()))
    assert worst < 1e-3, worst


def test_the_propagated_span_grows_with_the_arc_not_its_square():
    """One day and four days of passes: the sweep integrates each chunk once over its own span (its
    steps plus the light-time margin), so the propagated seconds stay near the arc's length, and
    four days integrate about four times one day's steps. From the epoch every chunk, the 4-day
    arc's ~50 segments would integrate ~25 arcs."""
    out = {}
    for days in (1.0, 4.0):
        pb, sw = _sweep(days, restarts=True)
        arc = float(sw.t_s[-1] - sw.t_s[0])
        out[days] = (sw.propagated_s / arc, sw.integrated_steps, len(sw.segments))
    assert out[4.0][2] > 40, out
    for ratio, _, _ in out.values():
        assert 1.0 <= ratio < 1.05, out
    assert 3.0 < out[4.0][1] / out[1.0][1] < 5.0, out


def test_a_full_force_reference_restarts_at_each_segment_and_stays_the_epochs_trajectory():
    """The full model (DOP853, the degree-2 field, the Sun and the Moon) restarts its reference at each
    tracking segment like the Taylor models: chained over 2 days and 20 segments (without restarts
    through the filter's state) it stays on the trajectory integrated once from the epoch (1.5e-5 m
    and 1.3e-6 m/s measured; 1.8 cm with the degree-7 fit whose velocities missed DOP853's at the
    steps' ends; a restart 1e-5 s off its time is 7 cm at once, at the epoch's time instead of its
    own metres), and the propagated span stays near the arc, where integrating every chunk from the
    epoch would propagate ~N/2 arcs over N segments."""
    pb, sw = _sweep(2.0, restarts=False, force="full")
    assert len(sw.segments) > 15
    whole = pb.trajectory(pb.x0, cover=sw.t_s)
    err = np.abs(sw.z_ref[:, :6] * sw.scales[:6] - whole.state(sw.t_s))
    assert err[:, :3].max() < 1e-3 and err[:, 3:].max() < 1e-5, (err[:, :3].max(), err[:, 3:].max())
    arc = float(sw.t_s[-1] - sw.t_s[0])
    assert 1.0 <= sw.propagated_s / arc < 1.05, sw.propagated_s / arc


def test_the_full_models_steps_meet_without_a_jump():
    """The full model's trajectory is one polynomial per DOP853 step (position, the velocity its
    derivative): at a step's end its polynomial and the next step's agree to 3.5e-8 m and 9e-13 m/s
    (measured: the fit made on the curvature, the end slopes the step's velocities). Fitted to the 8
    raw 7e6 m positions alone the joins were off by 1.3e-5 m and 4.8e-7 m/s (on the curvature alone
    6.7e-8 m/s, the dense output's own error), which a filter's time update between the reference's
    states takes for changes of the orbit: iterated, a full-force filter restarted per segment
    stalled at 0.02 sigma (docs/filter.md)."""
    from numpy.polynomial import polynomial as P

    pb, _ = _problem(2.0, "full")
    run = pb.trajectory(pb.x0, cover=[20000.0]).runs[-1]
    c = run.coefficients[:, 0]                            # (steps, 3, degree + 1), seconds from the step's start
    h = np.diff(run.step_times_s)
    k = np.arange(5, h.size - 1)                          # past DOP853's first, short, steps
    end = np.stack([P.polyval(h[j], c[j].T) for j in k])
    end_v = np.stack([P.polyval(h[j], P.polyder(c[j].T)) for j in k])
    jump, jump_v = np.abs(end - c[k + 1, :, 0]), np.abs(end_v - c[k + 1, :, 1])
    assert jump.max() < 3e-7 and jump_v.max() < 1e-10, (jump.max(), jump_v.max())

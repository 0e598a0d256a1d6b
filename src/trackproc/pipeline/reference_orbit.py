"""An orbit against an independent reference ephemeris (ILRS CPF): distance over the reference's span.

The state is propagated with the given force model to every CPF epoch (UTC) and compared in
GCRF (the CPF's ITRF positions through :func:`trackproc.io.cpf.cpf_gcrf`); the distance is
also split into radial, along-track and cross-track components of the propagated orbit.
Used by ``propagate --compare CPF`` and the LAGEOS-2 validation test.
"""

from __future__ import annotations

import numpy as np

from trackproc.dynamics import propagator
from trackproc.dynamics import timescales as ts
from trackproc.io.cpf import cpf_gcrf
from trackproc.isotime import iso_utc


def compare_with_cpf(state, cpf, *, force: str = "j2", eop=None, propagate_kwargs: dict | None = None) -> dict:
    """Distances (m) between ``state`` (GCRF, :class:`~trackproc.io.statefile.State`) propagated
    with ``force`` and the CPF positions: ``{"n", "max_m", "rms_m", "rms_radial_m",
    "rms_along_m", "rms_cross_m", "start", "end", "distance_m" (N,)}``."""
    times = np.asarray(cpf.times, dtype="datetime64[ns]")
    jd = ts.datetime64_to_jd_utc(times)
    t_s = np.asarray(ts.seconds_since(jd, ts.datetime64_to_jd_utc(np.datetime64(state.epoch, "ns"))), float)
    traj = propagator.propagate(state.r_m, state.v_m_s, state.epoch, t_s, force=force, eop=eop,
                                **(propagate_kwargs or {})).raise_for_outcome()
    rv = traj.state(t_s)
    ref = cpf_gcrf(cpf, eop)
    d = rv[:, :3] - ref
    r_hat = rv[:, :3] / np.linalg.norm(rv[:, :3], axis=1)[:, None]
    h = np.cross(rv[:, :3], rv[:, 3:])
    c_hat = h / np.linalg.norm(h, axis=1)[:, None]
    a_hat = np.cross(c_hat, r_hat)
    dist = np.linalg.norm(d, axis=1)

    def rms(x):
        return float(np.sqrt(np.mean(x * x)))

    return {"n": int(len(dist)), "max_m": float(dist.max()), "rms_m": rms(dist),
            "rms_radial_m": rms(np.einsum("ij,ij->i", d, r_hat)), "rms_along_m": rms(np.einsum("ij,ij->i", d, a_hat)),
            "rms_cross_m": rms(np.einsum("ij,ij->i", d, c_hat)), "start": iso_utc(times[0], 3),
            "end": iso_utc(times[-1], 3), "distance_m": dist}


class CpfTrajectory:
    """The CPF positions (GCRF) as a trajectory: Lagrange interpolation of degree 9 over the 10
    nearest epochs (its error scales as h^10: 0.14 m at most with LAGEOS epochs 600 s apart,
    measured by dropping every other node, hence ~0.1 mm at the CPF's 300 s), velocity and acceleration by central differences of the
    interpolant (h = 0.5 s). ``t`` in seconds from ``epoch``. ``stm`` is zero: a reference
    orbit has no parameters (for modelling measurements through
    :func:`trackproc.models.observation.evaluate`)."""

    ORDER = 10

    def __init__(self, cpf, epoch, eop=None):
        ref = ts.datetime64_to_jd_utc(np.datetime64(epoch, "ns"))
        self.t_nodes = np.asarray(ts.seconds_since(ts.datetime64_to_jd_utc(cpf.times), ref), float)
        self.r_nodes = cpf_gcrf(cpf, eop)
        if len(self.t_nodes) < self.ORDER:
            raise ValueError("a CPF trajectory needs at least 10 epochs")

    def covers(self, t) -> np.ndarray:
        """True where ``t`` lies inside the CPF's span."""
        t = np.asarray(t, float)
        return (t >= self.t_nodes[0]) & (t <= self.t_nodes[-1])

    def position(self, t) -> np.ndarray:
        t = np.atleast_1d(np.asarray(t, float))
        k = np.clip(np.searchsorted(self.t_nodes, t) - self.ORDER // 2, 0, len(self.t_nodes) - self.ORDER)
        idx = k[:, None] + np.arange(self.ORDER)[None, :]
        x = self.t_nodes[idx]                                    # (N, m)
        diff = t[:, None] - x                                    # (N, m)
        den = x[:, :, None] - x[:, None, :]                      # (N, m, m)
        eye = np.eye(self.ORDER, dtype=bool)
        num = np.where(eye[None], 1.0, diff[:, None, :])
        den = np.where(eye[None], 1.0, den)
        w = np.prod(num / den, axis=2)                           # Lagrange basis at t
        return np.einsum("nm,nmk->nk", w, self.r_nodes[idx])

    def state(self, t, derivative: int = 0) -> np.ndarray:
        h = 0.5
        t = np.atleast_1d(np.asarray(t, float))
        p0, pp, pm = self.position(t), self.position(t + h), self.position(t - h)
        vel = (pp - pm) / (2 * h)
        if derivative == 0:
            return np.hstack([p0, vel])
        return np.hstack([vel, (pp - 2 * p0 + pm) / (h * h)])

    def stm(self, t) -> np.ndarray:
        return np.zeros((np.atleast_1d(t).size, 6, 6))

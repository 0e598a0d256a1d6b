"""An orbit against an independent reference ephemeris (ILRS CPF): distance over the reference's span.

The state is propagated with the given force model to every CPF epoch (UTC) and compared in
GCRF (the CPF's ITRF positions through :func:`trackproc.io.cpf.cpf_gcrf`); the distance is
also split into radial, along-track and cross-track components of the propagated orbit.
Used by ``propagate --compare CPF`` and the LAGEOS-2 validation test.
"""

from __future__ import annotations

import numpy as np


def compare_with_cpf(state, cpf, *, force: str = "j2", eop=None, propagate_kwargs: dict | None = None) -> dict:
    """Distances (m) between ``state`` (GCRF, :class:`~trackproc.io.statefile.State`) propagated
    with ``force`` and the CPF positions: ``{"n", "max_m", "rms_m", "rms_radial_m",
    "rms_along_m", "rms_cross_m", "start", "end", "distance_m" (N,)}``."""
    from trackproc.dynamics import propagator
    from trackproc.dynamics import timescales as ts
    from trackproc.io.cpf import cpf_gcrf
    from trackproc.isotime import iso_utc

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

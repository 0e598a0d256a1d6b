"""What one pass determines of the state (:func:`observability`) and the profile covariance along what it cannot
see (:func:`profile_mixture`).
"""

from __future__ import annotations

from dataclasses import dataclass, field
from typing import Callable, Optional

import numpy as np



#: State directions in the radial / along-track / cross-track frame.
RTN_NAMES = ("radial_m", "along_m", "cross_m", "radial_m_s", "along_m_s", "cross_m_s")


@dataclass
class Observability:
    """What one pass determines: see :func:`observability`.

    ``singular_values``: of the whitened Jacobian of every estimated parameter, the state columns
    in units of the reference sigma and the others in their drivers' scales; ``names`` its
    columns. ``state_singular_values`` (6,): of the state part after projecting the other
    parameters out, in units of the reference (a-priori) sigma: ``s > 1`` means the pass alone
    determines that direction better than the reference; ``gain`` ``1/√(1 + s²)`` is the
    posterior/prior sigma ratio along it (with the reference as the prior). ``directions`` (6, 6):
    rows are the corresponding state directions, RTN components (m, m/s) of a one-reference-sigma
    perturbation; ``unobservable`` the indices with ``s < threshold``; ``reference_sigma`` the
    RTN sigmas of the reference (6,); ``posterior_sigma_rtn``: the solution's RTN sigmas;
    ``rotation_alignment``: |cos| between the weakest direction and a rotation of the orbit about
    the station's geocentric axis (which leaves every station-satellite distance unchanged), in
    the reference metric (1 = that rotation is what the pass cannot see).
    """

    names: list
    singular_values: np.ndarray
    state_singular_values: np.ndarray
    gain: np.ndarray
    directions: np.ndarray
    unobservable: list
    reference: str
    reference_sigma_rtn: np.ndarray
    posterior_sigma_rtn: np.ndarray
    threshold: float = 1.0
    rotation_alignment: Optional[float] = None
    notes: list = field(default_factory=list)
    #: (6, 6) GCRF: column i is direction i (``L vᵢ``); ``dual`` row i picks its coefficient (``vᵢᵀ L⁻¹``)
    basis: Optional[np.ndarray] = None
    dual: Optional[np.ndarray] = None
    #: the refinement's correction (refined - stale) split by :meth:`split`, RTN (m, m/s)
    correction_rtn: Optional[dict] = None

    def split(self, difference) -> tuple[np.ndarray, np.ndarray]:
        """``(seen, unseen)``: a GCRF state difference (6,) (an error, a correction) split into
        the part along the directions the pass determines and the part along those it cannot
        see (:attr:`unobservable`); ``seen + unseen = difference``. The split is the one of the
        report (the reference metric), so the unseen part is what only the a-priori can bound."""
        d = np.asarray(difference, float)
        weak = list(self.unobservable)
        unseen = self.basis[:, weak] @ (self.dual[weak] @ d) if weak else np.zeros(6)
        return d - unseen, unseen

    def direction_text(self, i: int, threshold: float = 0.2) -> str:
        """``+9.9 km along -1.3 km radial ...``: the main RTN components of direction ``i``."""
        d = self.directions[i]
        k = int(np.argmax(np.abs(d / np.maximum(self.reference_sigma_rtn, 1e-300))))
        if d[k] < 0:
            d = -d
        weight = np.abs(d) / np.maximum(self.reference_sigma_rtn, 1e-300)
        weight = weight / max(weight.max(), 1e-300)
        parts = []
        for j in np.argsort(-weight):
            if weight[j] < threshold:
                continue
            label = RTN_NAMES[j].replace("_m_s", " velocity").replace("_m", "")
            value = d[j]
            if j < 3:
                parts.append(f"{value / 1e3:+.3g} km {label}")
            else:
                parts.append(f"{value:+.3g} m/s {label}")
        return " ".join(parts)

    def as_dict(self) -> dict:
        return {
            "reference": self.reference,
            "threshold": self.threshold,
            "singular_values": {"parameters": list(self.names), "values": self.singular_values.tolist()},
            "state_singular_values": self.state_singular_values.tolist(),
            "posterior_to_reference_sigma": self.gain.tolist(),
            "directions_rtn": [dict(zip(RTN_NAMES, row.tolist())) for row in self.directions],
            "directions_text": [self.direction_text(i) for i in range(len(self.directions))],
            "unobservable": [self.direction_text(i) for i in self.unobservable],
            "reference_sigma_rtn": dict(zip(RTN_NAMES, self.reference_sigma_rtn.tolist())),
            "weakest_vs_rotation_about_station_axis": self.rotation_alignment,
            "posterior_sigma_rtn": dict(zip(RTN_NAMES, self.posterior_sigma_rtn.tolist())),
            "correction_rtn": self.correction_rtn,
            "notes": list(self.notes),
        }


#: Gauss-Hermite nodes per unseen direction of :func:`profile_mixture`: 3 (0, ±√3) integrate the
#: mixture exactly when the solution moves quadratically with the held coordinate; against 5
#: nodes every sigma agreed to 0.1 % on 40 simulated passes and to 1e-4 on the seven DopTrack
#: development passes, for half the constrained solves (issue 19).
PROFILE_NODES = 3


def profile_mixture(solve_fixed: Callable[[float], tuple], x_hat, sigma: float, nodes: int = PROFILE_NODES):
    """Covariance about ``x_hat`` of a posterior that is curved along one direction.

    ``solve_fixed(target) -> (x_k, C_k)``: the solution with that direction's coordinate held
    at ``target`` and its covariance conditional on it; ``sigma`` the coordinate's linear
    posterior sigma. With the probabilists' Gauss-Hermite nodes ``t_k`` and weights ``w_k``
    (normalised), ``Σ w_k (C_k + (x_k - x̂)(x_k - x̂)ᵀ)`` at ``target = t_k σ``: equal to the linear
    covariance when the problem is linear, and it carries the spread of the valley the
    estimate slides along when it is not (one pass: the rotation about the station's axis).
    """
    t, w = np.polynomial.hermite_e.hermegauss(nodes)
    w = w / w.sum()
    x_hat = np.asarray(x_hat, float)
    out = np.zeros((x_hat.size, x_hat.size))
    for tk, wk in zip(t, w):
        x_k, c_k = solve_fixed(float(tk) * sigma)
        d = np.asarray(x_k, float) - x_hat
        out += wk * (np.asarray(c_k, float) + np.outer(d, d))
    return out


def observability(jacobian, sigma, names, rtn, reference_covariance, posterior_covariance, *,
                  other_scales=None, reference: str = "", threshold: float = 1.0,
                  station_axis=None, state=None) -> Observability:
    """Observability of the state from one pass.

    ``jacobian`` (N, n) of the model at the solution (state x..vz in the first 6 columns, GCRF),
    ``sigma`` (N,) the data sigmas, ``rtn`` (6, 6) the map of GCRF state errors to RTN ones
    (:func:`trackproc.dynamics.rtn.rtn_jacobian` with ``rotating=False``),
    ``reference_covariance`` (6, 6) GCRF: the a-priori covariance (or a nominal one) that sets
    the units; ``posterior_covariance`` (6, 6) GCRF; ``other_scales`` (n - 6,) column scales
    of the other parameters for the plain singular values.

    The state information ``Λ = J_sᵀ (I - P_b) J_s`` (``P_b`` the projector on the bias columns:
    the biases are estimated, so only what they cannot absorb informs the state) is whitened by
    the reference, ``M = Lᵀ Λ L`` with ``reference = L Lᵀ``; its eigenvalues are the squared
    state singular values and ``L u`` the directions (rotated to RTN).
    """
    jw = np.asarray(jacobian, float) / np.asarray(sigma, float)[:, None]
    n = jw.shape[1]
    ref = np.asarray(reference_covariance, float)
    chol = np.linalg.cholesky(ref)
    js = jw[:, :6] @ chol
    scales_other = np.ones(n - 6) if other_scales is None else np.asarray(other_scales, float)
    if n > 6:
        jb = jw[:, 6:] * scales_other[None, :]
        qb, rb = np.linalg.qr(jb)
        keep = np.abs(np.diag(rb)) > 1e-12 * max(np.abs(np.diag(rb)).max(), 1e-300)
        qb = qb[:, keep]
        js_proj = js - qb @ (qb.T @ js)
        full = np.hstack([js, jb])
    else:
        js_proj = js
        full = js
    sv_full = np.linalg.svd(full, compute_uv=False)
    _, s, vt = np.linalg.svd(js_proj, full_matrices=False)
    big = np.asarray(rtn, float)
    directions = (big @ chol @ vt.T).T                           # rows: RTN of L u_i
    ref_rtn = np.sqrt(np.clip(np.diag(big @ ref @ big.T), 0.0, None))
    post_rtn = np.sqrt(np.clip(np.diag(big @ np.asarray(posterior_covariance, float) @ big.T), 0.0, None))
    weak = [i for i in range(6) if s[i] < threshold]
    align = None
    if station_axis is not None and state is not None:
        k = np.asarray(station_axis, float) / np.linalg.norm(station_axis)
        st = np.asarray(state, float)
        t_w = np.linalg.solve(chol, np.r_[np.cross(k, st[:3]), np.cross(k, st[3:6])])
        align = float(abs(vt[-1] @ t_w) / np.linalg.norm(t_w))
    return Observability(names=list(names), singular_values=sv_full, state_singular_values=s,
                         gain=1.0 / np.sqrt(1.0 + s * s), directions=directions, unobservable=weak,
                         reference=reference, reference_sigma_rtn=ref_rtn, posterior_sigma_rtn=post_rtn,
                         threshold=threshold, rotation_alignment=align, basis=chol @ vt.T,
                         dual=vt @ np.linalg.inv(chol))

"""The Earth's gravity field in normalised spherical harmonics, acting in ITRF.

The potential ``U = GM/r + GM/R Σ_n Σ_m (R/r)^(n+1) P̄_nm(sin φ) (C̄_nm cos mλ + S̄_nm sin mλ)``
is evaluated with Cunningham's recursion of the solid harmonics ``V_nm``, ``W_nm``
(Montenbruck & Gill, *Satellite Orbits*, 2000, eqs. 3.27-3.33), here in a fully normalised
form ``V̄_nm = V_nm / N_nm`` with ``N_nm² = (n+m)! / ((2-δ_m0)(2n+1)(n-m)!)`` so that
``C_nm V_nm = C̄_nm V̄_nm`` and no term over- or underflows up to high degree. The recursion
is in Cartesian coordinates (no singularity at the poles) and vectorised over points: one
loop over the degree, numpy over the orders and the points.

Normalised recursion (derived from M&G eqs. 3.29-3.31 by the ratios of ``N_nm``):

    V̄_00 = R/r
    V̄_mm = f_m (x₀ V̄_m-1,m-1 - y₀ W̄_m-1,m-1),  W̄_mm = f_m (x₀ W̄_m-1,m-1 + y₀ V̄_m-1,m-1)
           f_1 = √3, f_m = √((2m+1)/(2m)) (m ≥ 2)
    V̄_nm = a_nm z₀ V̄_n-1,m - b_nm ρ V̄_n-2,m      (same for W̄)
           a_nm = √((2n-1)(2n+1)/((n-m)(n+m))),  b_nm = √((n+m-1)(n-m-1)(2n+1)/((n+m)(n-m)(2n-3)))

with ``x₀ = xR/r²`` (likewise y₀, z₀) and ``ρ = R²/r²``; the accelerations are M&G eq. 3.33
with each ``V_n+1,k`` replaced by ``(N_n+1,k / N_nm) V̄_n+1,k``.
"""

from __future__ import annotations

from dataclasses import dataclass, field

import numpy as np

__all__ = ["GravityField"]


@dataclass(frozen=True, eq=False)
class GravityField:
    """Fully normalised Stokes coefficients ``C̄_nm``, ``S̄_nm`` (arrays ``[n, m]``) of one date.

    ``gm_m3_s2`` and ``radius_m`` are the model's own (ICGEM header); ``name`` and ``source``
    name it in outputs; ``tide_system`` as the file says (``tide_free``, ``zero_tide``).
    """

    gm_m3_s2: float
    radius_m: float
    cbar: np.ndarray
    sbar: np.ndarray
    name: str = "field"
    tide_system: str = "unknown"
    source: str = ""
    epoch: str = ""                  # date the time-variable terms were evaluated at (ISO UTC)
    _tables: dict = field(default_factory=dict, repr=False, compare=False)

    @property
    def degree(self) -> int:
        return self.cbar.shape[0] - 1

    @property
    def order(self) -> int:
        nz = np.nonzero((self.cbar != 0) | (self.sbar != 0))
        return int(nz[1].max()) if nz[1].size else 0

    def truncated(self, degree: int, order: int | None = None) -> "GravityField":
        """The field cut to ``degree`` x ``order`` (order <= degree)."""
        order = degree if order is None else order
        if degree < 0 or order < 0 or order > degree:
            raise ValueError(f"gravity field degree/order must satisfy 0 <= order <= degree; found {degree}x{order}")
        if degree > self.degree:
            raise ValueError(f"the gravity field {self.name} has degree {self.degree}; {degree} requested")
        c = self.cbar[:degree + 1, :degree + 1].copy()
        s = self.sbar[:degree + 1, :degree + 1].copy()
        c[:, order + 1:] = 0.0
        s[:, order + 1:] = 0.0
        return GravityField(self.gm_m3_s2, self.radius_m, c, s, self.name, self.tide_system, self.source, self.epoch)

    def j2(self) -> float:
        """Unnormalised J2 = -√5 C̄_20."""
        return -np.sqrt(5.0) * float(self.cbar[2, 0]) if self.degree >= 2 else 0.0

    # -- evaluation --------------------------------------------------------------------------
    def _coefficient_tables(self):
        """Index lists of the nonzero (n, m) terms and their normalisation ratios (cached)."""
        if self._tables:
            return self._tables
        nmax = self.degree
        mmax = self.order
        n_idx, m_idx = [], []
        for n in range(nmax + 1):
            for m in range(min(n, mmax) + 1):
                n_idx.append(n)
                m_idx.append(m)
        n_ = np.array(n_idx)
        m_ = np.array(m_idx)
        nf = n_.astype(float)
        mf = m_.astype(float)
        # N_{n+1,m}/N_nm, N_{n+1,m+1}/N_nm, N_{n+1,m-1}/N_nm (closed forms of the factorial ratios)
        k0 = np.sqrt((nf + mf + 1) / (nf - mf + 1) * (2 * nf + 1) / (2 * nf + 3))
        kp = np.sqrt((nf + mf + 2) * (nf + mf + 1) * (2 * nf + 1) / (2 * nf + 3) * np.where(m_ == 0, 0.5, 1.0))
        with np.errstate(divide="ignore", invalid="ignore"):
            km = np.sqrt((2 * nf + 1) / ((nf - mf + 2) * (nf - mf + 1) * (2 * nf + 3))
                         * np.where(m_ == 1, 2.0, 1.0))
        km = np.where(m_ == 0, 0.0, km)
        # Recursion coefficients for degree n, orders m < n (up to order mmax + 1)
        size = nmax + 2
        a = np.zeros((size, size))
        b = np.zeros((size, size))
        for n in range(1, size):
            for m in range(0, min(n, mmax + 2)):
                a[n, m] = np.sqrt((2 * n - 1) * (2 * n + 1) / ((n - m) * (n + m)))
                if n - m >= 2:
                    b[n, m] = np.sqrt((n + m - 1) * (n - m - 1) * (2 * n + 1) / ((n + m) * (n - m) * (2 * n - 3)))
        f = np.array([0.0, np.sqrt(3.0)] + [np.sqrt((2 * m + 1) / (2 * m)) for m in range(2, size)])
        f[0] = 1.0
        c, s = self.cbar[n_, m_], self.sbar[n_, m_]
        k0 = k0 * (nf - mf + 1)
        km = km * (nf - mf + 2) * (nf - mf + 1)
        # M&G eq. 3.33 folded into complex weights: a_x + i a_y = Σ p1 Z_n+1,m+1 + p2 conj(Z_n+1,m-1),
        # a_z = Re Σ p3 Z_n+1,m (for m = 0 the eq.'s own form: no halving, no m-1 term)
        kp_eff = np.where(m_ == 0, kp, 0.5 * kp)
        p1 = -kp_eff * (c - 1j * s)
        p2 = 0.5 * km * (c + 1j * s)
        p3 = -k0 * (c - 1j * s)
        size = nmax + 2
        self._tables.update(fprod=np.cumprod(f), n=n_, m=m_, a=a, b=b, c=c, s=s, p1=p1, p2=p2, p3=p3,
                            ip=(n_ + 1) * size + m_ + 1, im=(n_ + 1) * size + np.maximum(m_ - 1, 0),
                            i0=(n_ + 1) * size + m_)
        return self._tables

    def solid_harmonics(self, r_itrf) -> np.ndarray:
        """Normalised ``Z̄_nm = V̄_nm + i W̄_nm`` to degree N+1, order M+1: complex (P, N+2, N+2).

        V̄ and W̄ obey the same recursion, so they are carried as one complex number; the
        sectorals are a product, ``Z̄_mm = (Π f_k) (x₀ + i y₀)^m R/r``.
        """
        t = self._coefficient_tables()
        r = np.atleast_2d(np.asarray(r_itrf, float))
        R = self.radius_m
        r2 = np.einsum("ij,ij->i", r, r)
        x0, y0, z0 = (r * (R / r2)[:, None]).T
        rho = R * R / r2
        nmax, mmax = self.degree + 1, min(self.order + 1, self.degree + 1)
        Z = np.zeros((r.shape[0], nmax + 1, nmax + 1), complex)
        ms = np.arange(mmax + 1)
        diag = t["fprod"][:mmax + 1] * (x0 + 1j * y0)[:, None] ** ms * (R / np.sqrt(r2))[:, None]
        Z[:, ms, ms] = diag
        a, b = t["a"], t["b"]
        z0c, rhoc = z0[:, None], rho[:, None]
        for n in range(1, nmax + 1):
            k = min(n, mmax + 1)
            if n >= 2:
                Z[:, n, :k] = a[n, :k] * z0c * Z[:, n - 1, :k] - b[n, :k] * rhoc * Z[:, n - 2, :k]
            else:
                Z[:, n, :k] = a[n, :k] * z0c * Z[:, n - 1, :k]
        return Z

    def acceleration(self, r_itrf, *, central: bool = True) -> np.ndarray:
        """Acceleration (m/s²) at ITRF positions ``r_itrf`` (m, (P, 3) or (3,)), in ITRF.

        ``central=False`` leaves out the ``GM/r`` term (C̄_00), i.e. gives the perturbation.
        Implements Montenbruck & Gill (2000) eqs. 3.27-3.33 (Cunningham recursion), normalised.
        """
        t = self._coefficient_tables()
        one = np.ndim(r_itrf) == 1
        Z = self.solid_harmonics(r_itrf)
        zf = Z.reshape(Z.shape[0], -1)
        k = 0 if central else 1                     # the (0, 0) term is the first
        zp, zm, z0 = zf[:, t["ip"][k:]], zf[:, t["im"][k:]], zf[:, t["i0"][k:]]
        # einsum, not BLAS: a threaded zgemv spins on a loaded machine (13 points at 70x70: 33 ms
        # with OpenBLAS threads, under 3 ms without)
        axy = np.einsum("pj,j->p", zp, t["p1"][k:]) + np.einsum("pj,j->p", np.conj(zm), t["p2"][k:])
        az = np.einsum("pj,j->p", z0, t["p3"][k:]).real
        g = self.gm_m3_s2 / self.radius_m ** 2
        out = g * np.stack([axy.real, axy.imag, az], -1)
        return out[0] if one else out

    def potential(self, r_itrf) -> np.ndarray:
        """Potential ``U`` (m²/s², positive) at ITRF positions: ``GM/R Σ C̄ V̄ + S̄ W̄``."""
        t = self._coefficient_tables()
        z = self.solid_harmonics(r_itrf)[:, t["n"], t["m"]]
        return self.gm_m3_s2 / self.radius_m * (t["c"] * z.real + t["s"] * z.imag).sum(-1)

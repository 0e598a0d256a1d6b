"""The recurrence of :func:`trackproc.dynamics.measurement_spectra.series.series_sqrt`, compiled.

Seed 004 eq. 12, ``D(K) = (D2(K) - sum_{l=1..K-1} D(l) D(K-l)) / (2 D(0))``: the same products
summed in the same order (``l`` ascending, from 0.0) as numpy's ``einsum("sl,sl->s")`` of the
numpy path, so the same numbers bit for bit (IEEE arithmetic, no fastmath: no reassociation, no
fused multiply-add). One call instead of one ``einsum`` per order (24 at the Taylor engine's
order 26), which made the square root a quarter of a pass prediction's CPU.
"""

from __future__ import annotations

from trackproc.dynamics.jit import njit

__all__ = ["sqrt_orders"]


@njit(nogil=True)
def sqrt_orders(d2, d, inv2):
    """Orders 2.. of ``d`` (S, n), C-ordered, in place; orders 0 and 1 and ``inv2 = 0.5 / d[:, 0]``
    given."""
    n_seg, n = d2.shape
    for s in range(n_seg):
        for k in range(2, n):
            acc = 0.0
            for l in range(1, k):
                acc += d[s, l] * d[s, k - l]
            d[s, k] = (d2[s, k] - acc) * inv2[s]

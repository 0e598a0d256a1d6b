"""Replace the user's orbit, or keep it? One rule for ``refine``, ``estimate``, ``fit-tle`` and
``filter`` (docs/design.md, "Prior and decision").

A solution replaces the orbit the user already had only when it is expected to predict better:

1. **Declined.** The data contradict a *stated* a-priori (its accuracy is known: a TLE, a state
   file's covariance, ``--apriori-sigma``; :mod:`trackproc.methods.estimation.prior`): the likely
   culprit is the data (a time-tag error, an oscillator step, another satellite), not an orbit
   whose accuracy was measured. The prior is written with its own covariance, verdict ``suspect``
   (reason ``declined``), never a loosened a-priori that lets the data move the orbit by their own
   errors. Only a *default* a-priori (no stated accuracy) may be adapted to the data (``estimate``:
   also a stated one that data determining the state without it overrule; docs/estimate.md).
2. **Kept.** The solution predicts the position better than the prior with probability below
   :data:`REPLACE_PROBABILITY` at every time over the horizon (the next day by default):
   :func:`probability_better_over`, :func:`by_prediction`.
3. **Replaced** otherwise.
"""

from __future__ import annotations

import math
from dataclasses import dataclass, field
from typing import Optional

import numpy as np

#: A solution replaces the prior only when it predicts the position better with at least this
#: probability (0.5 is a coin toss). fit-tle's refusal rule, chosen on the DopTrack development days
#: (docs/fit-tle.md, "Refusal"); at 0.5 single passes would replace TLEs with covariances 4-10x too
#: small at the next pass (docs/refine.md, "Replace, keep or decline").
REPLACE_PROBABILITY = 0.9
#: The default horizon of the comparison (days after the solution epoch): the next day's passes.
HORIZON_DAYS = 1.0

#: The decisions, as the output files and the batch summary name them (an adapted a-priori is said
#: by the ``apriori_conflict`` reason and ``apriori_adapted`` beside the decision).
ACTIONS = ("replaced", "kept", "declined")


def probability_better(moved, covariance) -> tuple[float, float, float]:
    """The probability that a solution predicts a position better than the prior did, when the
    solution's prediction error is ``N(0, covariance)`` and it moves the prediction by ``moved``
    (``d``, m). The prior's error is then ``e − d``, and ``|e − d|² > |e|²`` exactly when
    ``e·u < |d|/2`` (``u = d/|d|``): probability ``Φ(|d| / (2 σ_u))``, ``σ_u² = uᵀ C u``. 0.5 when
    the solution does not move the prediction (a coin toss, not a gain); near 1 when it moves it by
    several σ. Returns ``(probability, |d|, σ_u)``. (fit-tle's rule; :func:`probability_better_over`
    over a span of times.)"""
    d = np.asarray(moved, float)
    size = float(np.linalg.norm(d))
    if size == 0.0:
        return 0.5, 0.0, 0.0
    u = d / size
    sigma = math.sqrt(max(float(u @ np.asarray(covariance, float) @ u), 0.0))
    if sigma == 0.0:
        return 1.0, size, 0.0
    return 0.5 * math.erfc(-size / (2.0 * sigma) / math.sqrt(2.0)), size, sigma


def probability_better_over(maps, change, covariance) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """:func:`probability_better` at each of K times: ``maps`` (K, 3, n) the position at time ``k``
    per state at the epoch, ``change`` the solution's change of that state, ``covariance`` its
    covariance. Returns ``(probability, |move| (m), σ_u (m))``, each (K,).

    The K times at once: stacked products, each the same sums in the same order as one
    :func:`probability_better` (the same numbers, bit for bit on the development machine)."""
    g = np.asarray(maps, float)
    c = np.asarray(covariance, float)
    d = g @ np.asarray(change, float)                              # (K, 3) moves
    cov = g @ c @ g.transpose(0, 2, 1)                             # (K, 3, 3) their covariances
    size = np.sqrt((d[:, None, :] @ d[:, :, None])[:, 0, 0])
    moved = size > 0.0
    u = np.divide(d, size[:, None], out=np.zeros_like(d), where=moved[:, None])
    sigma = np.sqrt(np.maximum(((u[:, None, :] @ cov) @ u[:, :, None])[:, 0, 0], 0.0))
    # no move: a coin toss (0.5); a move with no uncertainty along it: certain (1)
    p = [0.5 if not m else 1.0 if s == 0.0 else 0.5 * math.erfc(-a / (2.0 * s) / math.sqrt(2.0))
         for m, a, s in zip(moved.tolist(), size.tolist(), sigma.tolist())]
    return np.array(p, float), np.where(moved, size, 0.0), np.where(moved, sigma, 0.0)


@dataclass
class Decision:
    """What became of the prior: ``action`` (:data:`ACTIONS`), the ``reason`` in words, the
    ``probability`` that the solution predicts better at ``horizon_days`` (None when not computed),
    the prediction's move and its sigma there (m), and the a-priori test that fired (if any)."""

    action: str
    reason: str
    source: Optional[str] = None
    probability: Optional[float] = None
    horizon_days: Optional[float] = None
    moved_m: Optional[float] = None
    moved_sigma_m: Optional[float] = None
    test: dict = field(default_factory=dict)

    @property
    def keeps_prior(self) -> bool:
        return self.action in ("kept", "declined")

    def as_dict(self) -> dict:
        out = {"action": self.action, "reason": self.reason, "apriori_source": self.source}
        for key in ("probability", "horizon_days", "moved_m", "moved_sigma_m"):
            value = getattr(self, key)
            if value is not None:
                out[{"probability": "probability_better"}.get(key, key)] = float(value)
        if self.test:
            out["apriori_test"] = dict(self.test)
        return out


def declined(source_text: str, test: dict, source: str = "stated") -> Decision:
    """The data contradict a stated a-priori (``test``: the a-priori test that fired)."""
    said = f"{test['test']} chi2 {test['statistic']:.4g} over {test['dof']}, limit {test['limit']:.3g}"
    return Decision("declined", f"declined: the data contradict {source_text} ({said}); its accuracy is stated, "
                                "so the data are the likely culprit: the prior is kept with its own covariance",
                    source=source, test={k: test[k] for k in ("test", "statistic", "dof", "limit", "conflict")})


def by_prediction(maps, times_days, change, covariance, horizon_days: float, source: Optional[str] = None,
                  probability: Optional[float] = None) -> Decision:
    """Replace or keep: the solution replaces the prior when it predicts the position better with at
    least ``probability`` at some time over the ``horizon_days`` after the epoch
    (:func:`probability_better_over` at ``times_days``, the epoch included; ``maps`` (K, 3, n)).
    Under the solution's own covariance it is never expected to predict worse (the probability is
    at least 0.5 everywhere), so a significant gain anywhere in the span is a gain; a move that is
    not significant anywhere leaves the prior, which predicts as well."""
    probability = REPLACE_PROBABILITY if probability is None else probability
    p, size, sigma = probability_better_over(maps, change, covariance)
    k = int(np.argmax(p))
    at = f"{float(times_days[k]) * 24.0:.3g} h after the epoch"
    said = (f"it moves the predicted position by {size[k]:.4g} m {at}, against its own {sigma[k]:.4g} m error "
            f"there: it predicts better than the prior with probability {p[k]:.3g} there ({p[-1]:.3g} "
            f"{horizon_days:g} d after the epoch)")
    kept = bool(p[k] < probability)
    return Decision("kept" if kept else "replaced",
                    (f"kept: the solution predicts no better over the {horizon_days:g} d after the epoch; "
                     f"at best {said.replace('it predicts better', 'better')} (< {probability:g})") if kept else
                    f"replaced: {said}",
                    source=source, probability=float(p[k]), horizon_days=horizon_days, moved_m=float(size[k]),
                    moved_sigma_m=float(sigma[k]))

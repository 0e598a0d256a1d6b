"""The full-force integrator's Dormand–Prince 8(5,3) tableau is SciPy's, number for number, and the
full-force module loads without ``scipy.integrate`` (why the tableau is copied)."""

import subprocess
import sys

import numpy as np

from trackproc.dynamics.forces import dop853_tableau as ours


def test_the_tableau_is_scipys():
    from scipy.integrate._ivp import dop853_coefficients as scipys

    for name in ("N_STAGES", "N_STAGES_EXTENDED", "INTERPOLATOR_POWER"):
        assert getattr(ours, name) == getattr(scipys, name)
    for name in ("C", "A", "B", "E3", "E5", "D"):
        assert np.array_equal(getattr(ours, name), getattr(scipys, name)), name


def test_the_order_conditions_hold():
    """An independent check of the numbers: the weights reproduce ∫₀¹ t^(k-1) dt = 1/k to order 8
    (the quadrature conditions ``B·C^(k-1) = 1/k``), and the rows of ``A`` sum to ``C``."""
    b, c, a = ours.B, ours.C[: ours.N_STAGES], ours.A[: ours.N_STAGES, : ours.N_STAGES]
    for k in range(1, 9):
        assert abs(b @ c ** (k - 1) - 1.0 / k) < 1e-14
    assert np.allclose(a.sum(axis=1), c, atol=1e-14)


def test_the_full_force_module_does_not_import_scipy_integrate():
    code = ("import sys, trackproc.dynamics.forces.compiled; "
            "print('scipy.integrate' in sys.modules)")
    out = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, check=True)
    assert out.stdout.strip() == "False"

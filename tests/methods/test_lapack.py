"""``methods/lapack.routines``: SciPy's own LAPACK functions without importing scipy.linalg."""

import subprocess
import sys

import numpy as np
import pytest

from trackproc.methods import lapack


@pytest.mark.subprocess
def test_routines_are_scipys_own_and_leave_scipy_linalg_unimported():
    """In a fresh interpreter the routines load without scipy.linalg (nor scipy's package), and
    once scipy.linalg is imported its ``lapack.dgeqrf`` etc. are the very objects handed out: the
    same compiled code, hence the same bits."""
    probe = ("import sys; from trackproc.methods.lapack import routines\n"
             "fns = routines('dgeqrf', 'dpbtrf', 'dtbtrs')\n"
             "before = sorted(m for m in sys.modules if m.startswith('scipy'))\n"
             "import scipy.linalg.lapack as L\n"
             "print(before, [f is getattr(L, n) for f, n in zip(fns, ('dgeqrf', 'dpbtrf', 'dtbtrs'))])")
    res = subprocess.run([sys.executable, "-c", probe], capture_output=True, text=True, check=True)
    assert res.stdout.split() == ["['scipy.linalg._flapack']", "[True,", "True,", "True]"], res.stdout + res.stderr


def test_routines_compute_scipys_factor(monkeypatch):
    """The QR and banded Cholesky against numpy's (independent LAPACK build): R's diagonal to
    1e-12 relative, L L^T = the band matrix; and without the wrapper module found, the package's
    functions are used."""
    rng = np.random.default_rng(3)
    a = rng.normal(size=(40, 5))
    dgeqrf, dpbtrf = lapack.routines("dgeqrf", "dpbtrf")
    qr, _, _, info = dgeqrf(np.array(a, order="F"))
    assert info == 0
    np.testing.assert_allclose(np.abs(np.diag(qr)[:5]), np.abs(np.diag(np.linalg.qr(a, mode="r"))), rtol=1e-12)
    n = 6
    ab = np.zeros((2, n))
    ab[0], ab[1, :-1] = 4.0, -1.0                      # tridiagonal, lower band storage
    chol, info = dpbtrf(ab, lower=1)
    low = np.diag(chol[0]) + np.diag(chol[1, :-1], -1)
    dense = 4.0 * np.eye(n) - np.eye(n, k=1) - np.eye(n, k=-1)
    assert info == 0 and np.allclose(low @ low.T, dense, atol=1e-14)
    from scipy.linalg import lapack as scipy_lapack

    monkeypatch.delitem(sys.modules, lapack._MODULE, raising=False)
    monkeypatch.setattr(lapack, "_load_wrapper", lambda: None)
    assert lapack._MODULE not in sys.modules
    assert lapack.routines("dgeqrf")[0] is scipy_lapack.dgeqrf

"""The full force model (issue 17): gravity field, ICGEM reader, SRP shadow, Harris-Priester,
the DOP853 propagation with its STM and parameter partials, each against an independent
reference (brute-force Legendre sums, the J2 formula, Kepler's closed form, central
differences, tabulated values)."""

from __future__ import annotations

import gzip

import numpy as np
import pytest
from scipy.special import factorial, lpmv

from trackproc.constants import J2, MU_EARTH, RE_EARTH
from trackproc.dynamics import gravity, kepler
from trackproc.dynamics.forces import ForceModel, GravityField, Spacecraft
from trackproc.dynamics.forces import drag, srp
from trackproc.dynamics.propagator import propagate
from trackproc.errors import InputError
from trackproc.io.icgem import default_field_path, load_field, read_icgem

EPOCH = np.datetime64("2020-04-05T00:00:00", "ns")
R0 = np.array([6878137.0, 0.0, 0.0])
V0 = 7612.6 * np.array([0.0, np.cos(np.radians(97.0)), np.sin(np.radians(97.0))])


def _random_field(n=8, seed=1):
    rng = np.random.default_rng(seed)
    c = np.tril(rng.normal(size=(n + 1, n + 1))) * 1e-6
    s = np.tril(rng.normal(size=(n + 1, n + 1))) * 1e-6
    s[:, 0] = 0.0
    c[0, 0], c[1], s[1] = 1.0, 0.0, 0.0
    return GravityField(3.986e14, 6378136.3, c, s)


def _brute_potential(f, r):
    """U from the textbook sum with scipy's associated Legendre functions (Condon-Shortley removed)."""
    x, y, z = r
    rr = np.linalg.norm(r)
    lat, lon = np.arcsin(z / rr), np.arctan2(y, x)
    u = 0.0
    for n in range(f.degree + 1):
        for m in range(n + 1):
            norm = np.sqrt((2 - (m == 0)) * (2 * n + 1) * factorial(n - m) / factorial(n + m))
            p = lpmv(m, n, np.sin(lat)) * (-1) ** m * norm
            u += (f.radius_m / rr) ** (n + 1) * p * (f.cbar[n, m] * np.cos(m * lon) + f.sbar[n, m] * np.sin(m * lon))
    return f.gm_m3_s2 / f.radius_m * u


@pytest.mark.parametrize("r", [[4.1e6, -3.3e6, 4.9e6], [-1.0e6, 2.0e6, -6.9e6], [7.0e6, 1.0, 2.0]])
def test_field_acceleration_is_the_gradient_of_the_textbook_potential(r):
    f = _random_field()
    r = np.array(r)
    assert f.potential(r)[0] == pytest.approx(_brute_potential(f, r), rel=1e-13)
    h = 1.0
    grad = np.array([(_brute_potential(f, r + h * e) - _brute_potential(f, r - h * e)) / (2 * h) for e in np.eye(3)])
    np.testing.assert_allclose(f.acceleration(r), grad, rtol=0, atol=5e-8)     # FD rounding ~1e-8 of ~5 m/s²


def test_degree_two_zonal_field_equals_the_j2_formula():
    c = np.zeros((3, 3))
    c[0, 0], c[2, 0] = 1.0, -J2 / np.sqrt(5.0)
    f = GravityField(MU_EARTH, RE_EARTH, c, np.zeros((3, 3)))
    r = np.array([[4.1e6, -3.3e6, 4.9e6], [0.0, 7.0e6, 1.0], [1.0, 2.0, -6.6e6]])
    np.testing.assert_allclose(f.acceleration(r), gravity.acceleration(r, MU_EARTH, J2, RE_EARTH), rtol=1e-14, atol=1e-15)


def test_high_degree_field_is_finite_and_small_beyond_j2():
    f = load_field(degree=70, date="2020-04-05")
    r = np.array([[6.6e6, 1.0e5, 1.0e5], [0.0, 0.0, 6.9e6], [0.0, 0.0, -6.9e6]])   # poles included
    a = f.acceleration(r, central=False)
    j2 = f.truncated(2).acceleration(r, central=False)
    assert np.all(np.isfinite(a))
    assert np.all(np.linalg.norm(a - j2, axis=1) < 1e-3 * np.linalg.norm(j2, axis=1) + 1e-3)


def test_shipped_field_and_time_variable_terms():
    path = default_field_path()
    assert path.is_file() and path.stat().st_size < 500_000
    f0 = read_icgem(path, 4)                               # no date: the gfct epoch (2005-01-01)
    assert f0.name == "EIGEN-6S" and f0.gm_m3_s2 == 3.986004415e14 and f0.radius_m == 6378136.46
    at_t0 = -4.84165299820e-04 + 4.10019292536e-11 + 3.33920225943e-11           # gfct + the cosines at t0
    assert f0.cbar[2, 0] == pytest.approx(at_t0, rel=1e-15) and f0.epoch.startswith("2005-01-01")
    f = read_icgem(path, 4, date="2020-04-05")
    dt = (np.datetime64("2020-04-05") - np.datetime64("2005-01-01")).astype(float) / 365.25
    w = 2 * np.pi * dt
    expected = (-4.84165299820e-04 - 1.26059939709e-11 * dt + 4.10019292536e-11 * np.cos(w)
                + 5.32367408468e-11 * np.sin(w) + 3.33920225943e-11 * np.cos(2 * w) - 2.44369818145e-11 * np.sin(2 * w))
    assert f.cbar[2, 0] == pytest.approx(expected, rel=1e-15, abs=1e-22)
    t = read_icgem(path, 10, 3)
    assert t.degree == 10 and t.order == 3 and np.all(t.cbar[:, 4:] == 0)


def _write(tmp_path, text, name="f.gfc"):
    p = tmp_path / name
    p.write_text(text)
    return p


HEAD = ("begin_of_head\nmodelname TEST\nearth_gravity_constant 3.986004415E+14\nradius 6378136.3\n"
        "max_degree 2\nnorm fully_normalized\nerrors formal\nend_of_head\n")


def test_icgem_20_format_and_bad_files(tmp_path):
    body = ("gfc 0 0 1.0 0.0 0 0\ngfc 2 1 0 0 0 0\ngfc 2 2 0 0 0 0\ngfct 2 0 -4.8e-4 0.0 0 0 20000101.0000 20100101.0000\n"
            "gfct 2 0 -4.9e-4 0.0 0 0 20100101.0000 20500101.0000\n"
            "trnd 2 0 1.0e-11 0.0 0 0 20100101.0000 20500101.0000\n"
            "acos 2 0 2.0e-11 0.0 0 0 20100101.0000 20500101.0000 1.0\n")
    f = read_icgem(_write(tmp_path, HEAD + body), date="2011-01-01")
    dt = 365.0 / 365.25
    assert f.cbar[2, 0] == pytest.approx(-4.9e-4 + 1e-11 * dt + 2e-11 * np.cos(2 * np.pi * dt), rel=1e-14)
    assert read_icgem(_write(tmp_path, HEAD + body), date="2005-01-01").cbar[2, 0] == -4.8e-4
    gz = tmp_path / "f.gfc.gz"
    gz.write_bytes(gzip.compress((HEAD + body).encode()))
    assert read_icgem(gz, date="2011-01-01").cbar[2, 0] == f.cbar[2, 0]
    cases = [(HEAD + "gfc 2 0 abc 0 0 0\n", "row 9"), (HEAD + "gfc 3 0 1e-6 0 0 0\n", "max_degree"),
             (HEAD + "xyz 2 0 1 0 0 0\n", "unknown line key"), (HEAD.replace("radius 6378136.3\n", ""), "radius"),
             (HEAD + "acos 2 0 1e-11 0 0 0\n", "period"), ("gfc 0 0 1 0\n", "header"),
             # the header against the content: missing terms, a term twice, non-Earth constants
             (HEAD + "gfc 2 0 -4.8e-4 0 0 0\n", "L=2 M=1 missing"),
             (HEAD + "gfc 2 0 -4.8e-4 0 0 0\ngfc 2 0 -4.9e-4 0 0 0\n", "listed twice"),
             (HEAD + body + "gfct 2 0 -4.9e-4 0.0 0 0 20100101.0000 20500101.0000\n", "listed twice"),
             (HEAD.replace("radius 6378136.3", "radius inf"), "radius"),
             (HEAD.replace("radius 6378136.3", "radius 6378.1363"), "radius"),
             (HEAD.replace("max_degree 2", "max_degree 100000000"), "max_degree"),
             (HEAD + "gfc 2 0 nan 0 0 0\ngfc 2 1 0 0 0 0\ngfc 2 2 0 0 0 0\n", "L=2 M=0")]
    for text, words in cases:
        with pytest.raises(InputError, match=words) as info:
            read_icgem(_write(tmp_path, text, "bad.gfc"))
        assert "bad.gfc" in str(info.value) and "\n" not in str(info.value)
    cut = tmp_path / "cut.gfc.gz"
    cut.write_bytes(gzip.compress((HEAD + body * 200).encode())[:300])
    with pytest.raises(InputError, match="cut short"):
        read_icgem(cut)
    with pytest.raises(InputError, match="--gravity"):
        read_icgem(_write(tmp_path, HEAD + body), degree=361)


def test_shadow_fraction_closed_forms():
    sun = np.array([1.496e11, 0.0, 0.0])
    pts = np.array([[7.0e6, 0.0, 0.0], [-7.0e6, 0.0, 0.0], [0.0, 7.0e6, 0.0]])
    np.testing.assert_array_equal(srp.shadow_fraction(pts, sun, 6378137.0), [1.0, 0.0, 1.0])
    # along the shadow edge the fraction goes monotonically from 0 to 1 through the penumbra
    ys = np.linspace(6.30e6, 6.46e6, 200)
    nu = srp.shadow_fraction(np.stack([np.full_like(ys, -7.0e6), ys, np.zeros_like(ys)], 1), sun, 6378137.0)
    assert nu[0] == 0.0 and nu[-1] == 1.0 and np.all(np.diff(nu) >= 0) and 0 < nu[100] < 1


def test_harris_priester_nodes_and_bulge():
    sun = np.array([1.0, 0.0, 0.0])
    apex = np.array([np.cos(np.radians(30)), np.sin(np.radians(30)), 0.0])
    rho = drag.harris_priester(np.array([400e3, 400e3, 1200e3]), np.stack([apex, -apex, apex]) * 6.8e6, sun)
    assert rho[0] == pytest.approx(7.492e-12, rel=1e-12) and rho[1] == pytest.approx(2.249e-12, rel=1e-12)
    assert rho[2] == 0.0


@pytest.mark.slow
def test_point_mass_full_propagation_matches_kepler():
    """Degree 0, no other force: DOP853 + the dense polynomials against the universal-variable solution."""
    fm = ForceModel(load_field(degree=0), third_bodies=(), relativity=False)
    t = np.linspace(-3000.0, 86400.0, 41)
    traj = propagate(R0, V0, EPOCH, t, force=fm)
    ref = kepler.propagate(np.concatenate([R0, V0]), t, fm.gm_m3_s2)
    err = traj.state(t) - ref
    assert np.abs(err[:, :3]).max() < 2e-3 and np.abs(err[:, 3:]).max() < 2e-6


@pytest.mark.slow
def test_stm_and_parameter_partials_match_central_differences():
    sc = Spacecraft(mass_kg=100.0, srp_area_m2=1.0, cr=1.3, drag_area_m2=1.0, cd=2.2)
    fm = ForceModel(load_field(degree=6, date="2020-04-05"), srp=True, drag=True, spacecraft=sc,
                    estimated=("cr", "cd", "empirical_t"))
    T = 2000.0
    traj = propagate(R0, V0, EPOCH, [T], force=fm, stm=True)
    phi, dp = traj.stm(T), traj.parameter_partials(T)
    x0 = np.concatenate([R0, V0])
    num = np.zeros((6, 6))
    for j, h in enumerate([100.0] * 3 + [0.1] * 3):       # steps large against DOP853's step-selection noise
        e = np.zeros(6)
        e[j] = h
        plus = propagate((x0 + e)[:3], (x0 + e)[3:], EPOCH, [T], force=fm).state(T)
        minus = propagate((x0 - e)[:3], (x0 - e)[3:], EPOCH, [T], force=fm).state(T)
        num[:, j] = (plus - minus) / (2 * h)
    scale = np.abs(num).max(axis=0)
    assert np.all(np.abs(phi - num) / scale < 1e-4)
    for k, (name, h) in enumerate([("cr", 0.5), ("cd", 0.5), ("empirical_t", 1e-6)]):
        val = fm.parameter_values()[name]
        plus = propagate(R0, V0, EPOCH, [T], force=fm.with_parameters(**{name: val + h})).state(T)
        minus = propagate(R0, V0, EPOCH, [T], force=fm.with_parameters(**{name: val - h})).state(T)
        ref = (plus - minus) / (2 * h)
        assert np.abs(dp[:, k] - ref).max() < 1e-2 * np.abs(ref).max(), name


def test_force_model_names_itself():
    fm = ForceModel(load_field(degree=20, date="2020-04-05"))
    d = fm.describe()
    assert d["gravity_field"]["model"] == "EIGEN-6S" and d["gravity_field"]["degree"] == 20
    assert set(d["third_bodies"]) == {"sun", "moon"} and "Schwarzschild" in d["relativity"]
    assert fm.label() == "full (EIGEN-6S 20x20, sun+moon, relativity)"
    with pytest.raises(ValueError, match="mass"):
        ForceModel(load_field(degree=2), drag=True)

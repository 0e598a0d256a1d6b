"""Physical and geodetic constants, SI units, each with its source.

One module so that every output can name the constants it used (see
``force_model_constants``).
"""

#: Earth's gravitational parameter, m^3/s^2 (IERS Conventions 2010, EGM2008; WGS-84 G1762).
MU_EARTH = 3.986004418e14
#: Second zonal harmonic, unnormalized (EGM2008: -C20 * sqrt(5), C20 = -4.84165143790815e-4).
J2 = 1.0826266835531513e-3
#: Equatorial radius used with J2, m (WGS-84 semi-major axis).
RE_EARTH = 6378137.0
#: WGS-84 semi-major axis, m, and flattening (NIMA TR8350.2).
WGS84_A = 6378137.0
WGS84_F = 1.0 / 298.257223563
#: Nominal mean angular velocity of the Earth, rad/s (WGS-84; IERS Conventions 2010 Table 1.1).
OMEGA_EARTH = 7.292115e-5
#: Speed of light in vacuum, m/s (exact, SI).
C_LIGHT = 299792458.0
#: Mean Earth radius of the spherical model, m (seed 004: R = 6371 km).
R_SPHERE = 6371000.0
#: Seed 004 eq. 7: ratio of sidereal to solar rate and the rotation rate it uses.
SEED004_Q = 1.0027379
SEED004_OMEGA = 0.7292115e-4
#: Highest gravity-field degree the force model evaluates. A degree-n term at 200 km altitude is
#: attenuated by (R/r)^n (1.5e-5 at n = 360) on top of a coefficient of ~1e-9, below 1e-13 of the
#: central term, and the solid harmonics of each evaluated point take 16 (n+2)^2 bytes
#: (GravityField.solid_harmonics): 360 is EGM96's full degree, beyond what any orbit here sees.
MAX_GRAVITY_DEGREE = 360
#: Julian date of J2000.0 (TT) and seconds per day.
JD_J2000 = 2451545.0
DAY_S = 86400.0


def force_model_constants(force: str) -> dict:
    """The constants of a force model, to be written into every output that used it."""
    out = {"mu_m3_s2": MU_EARTH}
    if force == "j2":
        out.update({"j2": J2, "re_m": RE_EARTH})
    return out

"""Closed-form sphere and semi-infinite-body conduction (drumheat.models.sphere_conduction)."""

import math

import jax
import jax.numpy as jnp
import numpy as np
import pytest
from scipy import integrate

import drumheat  # noqa: F401
from drumheat.models import sphere_conduction as sc

# First eigenvalue and coefficient of the one-term series, as tabulated in heat-transfer texts
# (e.g. Incropera, Table 5.1, sphere; Bi = h r0 / k). Outside check, 4 decimals.
TABLE = {0.1: (0.5423, 1.0298), 1.0: (1.5708, 1.2732), 10.0: (2.8363, 1.9249)}


@pytest.mark.parametrize("Bi", sorted(TABLE))
def test_first_eigenvalue_against_table(Bi):
    lam = sc.sphere_eigenvalues(Bi, 5)
    C = sc.sphere_series_coefficients(lam)
    assert float(lam[0]) == pytest.approx(TABLE[Bi][0], abs=1e-4)
    assert float(C[0]) == pytest.approx(TABLE[Bi][1], abs=1e-4)


@pytest.mark.parametrize("Bi", [1e-3, 0.1, 1.0, 10.0, 1e3])
def test_eigenvalues_solve_equation(Bi):
    lam = np.asarray(sc.sphere_eigenvalues(Bi, 40))
    # 1 - lam cot(lam) = Bi, each root in ((k-1) pi, k pi)
    res = 1 - lam / np.tan(lam) - Bi
    assert np.max(np.abs(res)) < 1e-9 * max(1.0, Bi)
    k = np.arange(1, 41)
    assert np.all(lam > (k - 1) * np.pi) and np.all(lam < k * np.pi)


def test_eigenvalue_gradient_implicit_function():
    Bi = 2.0
    g = float(jax.grad(lambda b: sc.sphere_eigenvalues(b, 3)[0])(Bi))
    fd = (float(sc.sphere_eigenvalues(Bi + 1e-6, 3)[0]) - float(sc.sphere_eigenvalues(Bi - 1e-6, 3)[0])) / 2e-6
    assert g == pytest.approx(fd, rel=1e-6)


def test_mean_series_alternative_form():
    # sum C_k 3(sin - l cos)/l^3 exp(-l^2 Fo) == sum 6 Bi^2 exp(-l^2 Fo)/(l^2 (l^2 + Bi^2 - Bi))
    Bi, Fo = 3.0, 0.07
    lam = np.asarray(sc.sphere_eigenvalues(Bi, 80))
    alt = np.sum(6 * Bi**2 * np.exp(-(lam**2) * Fo) / (lam**2 * (lam**2 + Bi**2 - Bi)))
    assert float(sc.sphere_mean_temperature(Fo, Bi, 1.0, 0.0, 80)) == pytest.approx(alt, rel=1e-12)


@pytest.mark.parametrize("Bi", [0.1, 1.0, 10.0])
def test_series_energy_consistency(Bi):
    """d(mean)/dt of the series equals the surface loss from the series' own surface temperature."""
    Fo = 0.15
    dFo = 1e-5
    dm = (float(sc.sphere_mean_temperature(Fo + dFo, Bi, 1.0, 0.0)) - float(sc.sphere_mean_temperature(Fo - dFo, Bi, 1.0, 0.0))) / (2 * dFo)
    # rho c (4/3 pi R^3) dTm/dt = -alpha 4 pi R^2 T_s  ->  dTm/dFo = -3 Bi T_s   (T_inf = 0)
    Ts = float(sc.sphere_temperature(1.0, Fo, Bi, 1.0, 0.0))
    assert dm == pytest.approx(-3 * Bi * Ts, rel=1e-7)
    # profile volume integral equals the mean series
    r = np.linspace(0, 1, 2001)
    T = np.asarray(sc.sphere_temperature(jnp.asarray(r), Fo, Bi, 1.0, 0.0))
    mean = 3 * integrate.simpson(T * r**2, x=r)
    assert mean == pytest.approx(float(sc.sphere_mean_temperature(Fo, Bi, 1.0, 0.0)), rel=1e-8)


def test_series_limits():
    # small Bi: lumped exp(-3 Bi Fo)
    Bi, Fo = 1e-4, 50.0
    assert float(sc.sphere_mean_temperature(Fo, Bi, 1.0, 0.0)) == pytest.approx(math.exp(-3 * Bi * Fo), rel=1e-4)
    # large Bi: Dirichlet sphere, 6/pi^2 sum exp(-k^2 pi^2 Fo)/k^2
    Fo = 0.05
    ref = 6 / math.pi**2 * sum(math.exp(-(k**2) * math.pi**2 * Fo) / k**2 for k in range(1, 200))
    assert float(sc.sphere_mean_temperature(Fo, 1e7, 1.0, 0.0, 100)) == pytest.approx(ref, rel=1e-5)
    # early time: centre still at T0
    assert float(sc.sphere_temperature(0.0, 0.005, 1.0, 1000.0, 300.0, 200)) == pytest.approx(1000.0, abs=1e-6)
    q = float(sc.sphere_surface_heat_flux(0.1, 2.0, 400.0, 300.0, 1.5, 0.01))
    assert q == pytest.approx(2.0 * 1.5 / 0.01 * (float(sc.sphere_temperature(1.0, 0.1, 2.0, 400.0, 300.0)) - 300.0))


def test_contact_temperature_slag_on_steel():
    # staltner digest sections 3, 9: slag lambda 1.58, c 1132, rho 2690; steel 50, 500, 7800
    bS = math.sqrt(1.58 * 1132 * 2690)
    bW = math.sqrt(50 * 500 * 7800)
    assert float(sc.effusivity(1.58, 1132.0, 2690.0)) == pytest.approx(bS, rel=1e-14)
    Ts, T4 = 1623.15, 373.15
    Tm = T4 + bS / (bS + bW) * (Ts - T4)  # [3.10]-[3.11] form
    assert float(sc.contact_temperature(Ts, bS, T4, bW)) == pytest.approx(Tm, rel=1e-14)
    assert T4 < Tm < Ts


def test_semi_infinite_flux_and_heat():
    b1, b2, T1, T2 = 2000.0, 14000.0, 1200.0, 400.0
    t = 0.3
    Tm = (b1 * T1 + b2 * T2) / (b1 + b2)
    q = float(sc.semi_infinite_contact_flux(T1, b1, T2, b2, t))
    assert q == pytest.approx(b1 * (T1 - Tm) / math.sqrt(math.pi * t), rel=1e-13)
    assert q == pytest.approx(b2 * (Tm - T2) / math.sqrt(math.pi * t), rel=1e-13)
    Qint = integrate.quad(lambda s: float(sc.semi_infinite_contact_flux(T1, b1, T2, b2, s)), 0, t, limit=200)[0]
    assert float(sc.semi_infinite_contact_heat(T1, b1, T2, b2, t)) == pytest.approx(Qint, rel=1e-6)


def test_internal_transient_nu_corrected_denominator():
    Bi, Fo = 2.5, 0.8
    nu0 = (math.sqrt(math.pi) + 10 * Bi * math.sqrt(Fo)) / (1 + 5 * Bi * math.sqrt(math.pi * Fo)) / math.sqrt(Fo)
    nuinf = (4 + 6 + Bi) / (1 + Bi / (2 * math.pi**2 / 3))
    ref = math.sqrt(nuinf**2 - 0.16 + (nu0 + 0.4) ** 2)
    assert float(sc.internal_transient_nu(Bi, Fo)) == pytest.approx(ref, rel=1e-13)
    # the garbled print "1 + 5 Bi sqrt(pi) Fo" gives a different number: the corrected one is used
    nu0_garbled = (math.sqrt(math.pi) + 10 * Bi * math.sqrt(Fo)) / (1 + 5 * Bi * math.sqrt(math.pi) * Fo) / math.sqrt(Fo)
    garbled = math.sqrt(nuinf**2 - 0.16 + (nu0_garbled + 0.4) ** 2)
    assert abs(garbled - ref) > 1e-3 * ref
    # limits (digest check): Nu_i_inf -> 2 pi^2/3 as Bi -> inf, -> 10 as Bi -> 0
    big = float(sc.internal_transient_nu(1e9, 1e6))
    # (Nu_i0 -> 2/sqrt(pi Fo) -> 0 at long times, so Nu_i -> Nu_i_inf)
    assert big == pytest.approx(2 * math.pi**2 / 3, rel=1e-3)
    small = float(sc.internal_transient_nu(1e-9, 1e9))
    assert small == pytest.approx(10.0, rel=1e-3)

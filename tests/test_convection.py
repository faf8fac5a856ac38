"""Convection correlations and the bed-level gas balance (drumheat.models.convection).

Reference values are computed here in plain Python (math module) from the formulas as written
in the digests, independently of the jnp implementation.
"""

import math

import jax
import jax.numpy as jnp
import numpy as np
import pytest
from scipy.integrate import solve_ivp

import drumheat  # noqa: F401  (float64)
from drumheat.models import convection as cv


def _gnielinski_vdi(Re, Pr):
    # staltner-slag-particle.md [3.25]-[3.28], kraychev (3-16)-(3-18), exact VDI form
    lam = 0.664 * math.sqrt(Re) * Pr ** (1.0 / 3.0)
    turb = 0.037 * Re**0.8 * Pr / (1.0 + 2.443 * Re ** (-0.1) * (Pr ** (2.0 / 3.0) - 1.0))
    return 2.0 + math.sqrt(lam**2 + turb**2)


@pytest.mark.parametrize("Re", [1.0, 100.0, 1.0e4, 3.0e5])
@pytest.mark.parametrize("Pr", [0.7, 7.0])
def test_gnielinski_exact_vdi(Re, Pr):
    assert float(cv.gnielinski_sphere_nu(Re, Pr)) == pytest.approx(_gnielinski_vdi(Re, Pr), rel=1e-13)


def test_gnielinski_hand_value():
    # Re = 1e4, Pr = 0.7 written out: Nu_lam = 0.664*100*0.7^(1/3) = 58.9566...
    lam = 0.664 * 100.0 * 0.7 ** (1 / 3)
    turb = 0.037 * 10.0**3.2 * 0.7 / (1 + 2.443 * 10.0**-0.4 * (0.7 ** (2 / 3) - 1))
    assert lam == pytest.approx(58.9568, rel=1e-5)
    assert float(cv.gnielinski_nu_lam(1e4, 0.7)) == pytest.approx(lam, rel=1e-14)
    assert float(cv.gnielinski_nu_turb(1e4, 0.7)) == pytest.approx(turb, rel=1e-14)
    assert float(cv.gnielinski_sphere_nu(1e4, 0.7)) == pytest.approx(2 + math.hypot(lam, turb), rel=1e-14)


def test_gnielinski_kraychev_variants_differ_as_documented():
    Re, Pr = 2.0e3, 0.7
    tab = 2 + math.hypot(
        0.664 * math.sqrt(Re) * Pr**0.33,
        0.037 * Re**0.8 * Pr / (1 + 2.443 * Re**-0.3 * (Pr**0.66 - 1)),
    )
    mathcad = 2 + math.hypot(
        0.664 * math.sqrt(Re) * Pr**0.39,
        0.037 * Re**0.8 * Pr / (1 + 2.443 * Re**-0.3 * (Pr**0.66 - 1)),
    )
    assert float(cv.gnielinski_sphere_nu(Re, Pr, "kraychev_tables")) == pytest.approx(tab, rel=1e-13)
    assert float(cv.gnielinski_sphere_nu(Re, Pr, "kraychev_mathcad")) == pytest.approx(mathcad, rel=1e-13)
    # digest 14.1: the Mathcad form gives a noticeably lower Nu than the exact form
    assert mathcad < _gnielinski_vdi(Re, Pr)


def test_fluidized_bed_sphere_form():
    # fluidized-bed-exercise.md section 3, L = d
    Re, Pr = 300.0, 0.69
    lam = (2 / (1 + 22 * Pr)) ** (1 / 6) * math.sqrt(Re * Pr)
    turb = 0.037 * Re**0.8 * Pr / (1 + 2.443 * Re**-0.1 * (Pr ** (2 / 3) - 1))
    assert float(cv.fluidized_bed_sphere_nu(Re, Pr)) == pytest.approx(2 + math.hypot(lam, turb), rel=1e-13)
    # At gas Prandtl numbers the two laminar parts agree closely (within 0.2 % here); what makes
    # the two sphere forms different is the characteristic length (d vs pi d/2), tested below.
    assert float(cv.nu_lam_all_pr(Re, Pr)) == pytest.approx(float(cv.gnielinski_nu_lam(Re, Pr)), rel=2e-3)


def test_sphere_alpha_lengths():
    w, d, nu, Pr, lam = 20.0, 2e-3, 1.5e-5, 0.71, 0.026
    L = math.pi * d / 2
    a1 = float(cv.sphere_alpha_gnielinski(w, d, nu, Pr, lam, "overflow"))
    assert a1 == pytest.approx(_gnielinski_vdi(w * L / nu, Pr) * lam / L, rel=1e-13)
    a2 = float(cv.sphere_alpha_gnielinski(w, d, nu, Pr, lam, "diameter"))
    Re = w * d / nu
    nu_d = 2 + math.hypot(
        (2 / (1 + 22 * Pr)) ** (1 / 6) * math.sqrt(Re * Pr),
        0.037 * Re**0.8 * Pr / (1 + 2.443 * Re**-0.1 * (Pr ** (2 / 3) - 1)),
    )
    assert a2 == pytest.approx(nu_d * lam / d, rel=1e-13)
    with pytest.raises(ValueError):
        cv.sphere_alpha_gnielinski(w, d, nu, Pr, lam, "radius")


def test_cylinder_crossflow():
    Re, Pr = 5.0e3, 0.7
    lam = (2 / math.sqrt(math.pi)) * math.sqrt(Re) * math.sqrt(Pr) / (1 + 1.973 * Pr**0.272 + 21.29 * Pr) ** (1 / 6)
    turb = 0.037 * Re**0.8 * Pr / (1 + 2.443 * Re**-0.1 * (Pr ** (2 / 3) - 1))
    assert float(cv.gnielinski_cylinder_crossflow_nu(Re, Pr)) == pytest.approx(0.3 + math.hypot(lam, turb), rel=1e-13)


def test_ranz_marshall_and_others():
    assert float(cv.ranz_marshall_nu(100.0, 0.7)) == pytest.approx(2 + 0.6 * 10 * 0.7 ** (1 / 3), rel=1e-14)
    assert float(cv.ranz_marshall_nu(0.0, 0.7)) == 2.0
    assert float(cv.kraychev_pascal_nu(500.0, 0.7)) == pytest.approx(2 + 0.459 * 500**0.55 * 0.7**0.33, rel=1e-14)
    assert float(cv.muschtaev_nu(500.0, 0.7)) == pytest.approx(2 + 0.51 * 500**0.52 * 0.7**0.33, rel=1e-14)
    assert float(cv.mcadams_nu(500.0)) == pytest.approx(0.415 * 500**0.6, rel=1e-14)
    assert float(cv.stagnant_film_nu(0.41)) == pytest.approx(2 / (1 - 0.59 ** (1 / 3)), rel=1e-14)
    assert float(cv.stagnant_film_nu(1.0 - 1e-12)) == pytest.approx(2.0, rel=1e-3)


def test_dimensionless_groups_and_regime():
    L, Tw, Tf, nu, w = 0.003, 1600.0, 400.0, 7e-5, 30.0
    Gr = float(cv.grashof(L, Tw, Tf, nu))
    assert Gr == pytest.approx(L**3 * 9.81 * (Tw - Tf) / ((Tw + Tf) / 2) / nu**2, rel=1e-14)
    Ar = float(cv.archimedes(L, Tw, Tf, w))
    Re = float(cv.reynolds(w, L, nu))
    assert Ar == pytest.approx(Gr / Re**2, rel=1e-12)
    assert int(cv.convection_regime(Ar)) == 0  # forced (digest: Ar << 0.25)
    assert list(np.asarray(cv.convection_regime(jnp.array([0.1, 1.0, 20.0])))) == [0, 1, 2]
    assert float(cv.prandtl(1.5e-5, 1.2, 1006.0, 0.026)) == pytest.approx(1.5e-5 * 1.2 * 1006 / 0.026)


def test_mixed_convection():
    a_f, a_n = 100.0, 40.0
    assert float(cv.mixed_convection_alpha(a_f, a_n, 4.0, True)) == pytest.approx((100**4 + 40**4) ** 0.25)
    assert float(cv.mixed_convection_alpha(a_f, a_n, 3.0, False)) == pytest.approx((100**3 - 40**3) ** (1 / 3))
    assert cv.MIXED_CONVECTION_EXPONENT["sphere_cross_flow"] == 4.0


def test_packed_bed_factor_and_interstitial_re():
    assert float(cv.packed_bed_factor(0.4)) == pytest.approx(1.9)
    assert float(cv.packed_bed_factor(1.0)) == 1.0
    assert float(cv.interstitial_reynolds(1.2, 6e-3, 20e-6, 0.4)) == pytest.approx(1.2 * 6e-3 / (0.4 * 20e-6))


def test_gradients_finite_and_correct():
    f = lambda Re: cv.gnielinski_sphere_nu(Re, 0.7)  # noqa: E731
    g = float(jax.grad(f)(3000.0))
    fd = (_gnielinski_vdi(3000.0 + 1e-3, 0.7) - _gnielinski_vdi(3000.0 - 1e-3, 0.7)) / 2e-3
    assert g == pytest.approx(fd, rel=1e-6)


# ---------------------------------------------------------------- bed-level model (exercise 4-5)

# a generic parameter set (not the exercise's result chain, which is withheld)
M1, CP1, MD2, CP2 = 60.0, 1700.0, 3.0, 1000.0
T1A, T2IN = 300.0, 20.0


def test_lmtd():
    a, b = 50.0, 20.0
    assert float(cv.log_mean_temperature_difference(a, b)) == pytest.approx((a - b) / math.log(a / b), rel=1e-14)
    # removable singularity: continuous and with finite gradient
    x = float(cv.log_mean_temperature_difference(30.0, 30.0 * (1 + 1e-6)))
    assert x == pytest.approx(30.0 * (1 + 0.5e-6), rel=1e-12)
    g = jax.grad(lambda b: cv.log_mean_temperature_difference(30.0, b))(30.0)
    assert float(g) == pytest.approx(0.5, rel=1e-6)


def test_bed_balance_closes_with_lmtd():
    k, A_f = 80.0, float(cv.bed_area_per_cross_section(M1, 6e-3, 630.0))
    assert A_f == pytest.approx(6 * 60 / (6e-3 * 630), rel=1e-14)
    ntu = float(cv.bed_ntu(k, A_f, MD2, CP2))
    T1 = 150.0
    T2out = float(cv.bed_outlet_gas_temperature(T1, T2IN, ntu))
    assert T2out == pytest.approx(T1 - (T1 - T2IN) * math.exp(-ntu), rel=1e-14)
    assert T2IN <= T2out <= T1
    dtlm = float(cv.log_mean_temperature_difference(T1 - T2IN, T1 - T2out))
    # f mdot cp (T2in - T2out) + k A dT_LM = 0   (section 4)
    assert MD2 * CP2 * (T2IN - T2out) + k * A_f * dtlm == pytest.approx(0.0, abs=1e-8 * MD2 * CP2 * T1)
    assert float(cv.bed_gas_heat_flux(T1, T2IN, ntu, MD2, CP2)) == pytest.approx(MD2 * CP2 * (T2out - T2IN), rel=1e-12)


def test_bed_closed_form_matches_ode():
    ntu = 0.8
    sol = solve_ivp(
        lambda t, y: [float(cv.bed_mean_temperature_rate(y[0], T2IN, ntu, M1, CP1, MD2, CP2))],
        (0.0, 150.0),
        [T1A],
        rtol=1e-10,
        atol=1e-10,
        t_eval=[50.0, 150.0],
    )
    closed = np.asarray(cv.batch_bed_mean_temperature(jnp.array([50.0, 150.0]), T1A, T2IN, ntu, M1, CP1, MD2, CP2))
    np.testing.assert_allclose(closed, sol.y[0], rtol=1e-8)
    # long-time limit
    assert float(cv.batch_bed_mean_temperature(1e6, T1A, T2IN, ntu, M1, CP1, MD2, CP2)) == pytest.approx(T2IN)
    # hand-written closed form
    rate = MD2 * CP2 / (M1 * CP1) * (1 - math.exp(-ntu))
    assert closed[1] == pytest.approx(T2IN - (T2IN - T1A) * math.exp(-rate * 150.0), rel=1e-13)


def test_series_coefficient():
    assert float(cv.series_coefficient(100.0, 50.0)) == pytest.approx(1 / (1 / 100 + 1 / 50))

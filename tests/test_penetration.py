"""Tests of the penetration model, drumheat/models/penetration.py.

Reference values are computed independently with the ``math`` module from the formulas of
reference/weigler-thermal-dem.md (written out here), plus the digest's own numeric checks.
"""

import math

import jax
import jax.numpy as jnp
import numpy as np
import pytest
from scipy.integrate import quad

import drumheat  # noqa: F401  (enables float64)
from drumheat.models import penetration as pm

G = 9.81


def hand_froude(rpm, D):
    # [1.4] Fr = (2 pi n)^2 D / (2 g), n = rpm / 60
    n = rpm / 60.0
    return (2 * math.pi * n) ** 2 * D / (2 * G)


def hand_alpha_bed(lam, rho, c, t_R):
    # [1.12] alpha_bed = 2/sqrt(pi) sqrt(rho c lambda / t_R)
    return 2.0 / math.sqrt(math.pi) * math.sqrt(rho * c * lam / t_R)


# --- digest numeric check: D = 0.25 m, 10 rpm ------------------------------------------------


def test_digest_note_10rpm():
    # digest section 2: Fr ~ 0.0140, N_mix ~ 6.81, t_R ~ 40.9 s
    assert float(pm.froude(10.0, 0.25)) == pytest.approx(0.0140, abs=5e-5)
    assert float(pm.mixing_number(10.0, 0.25)) == pytest.approx(6.81, abs=5e-3)
    assert float(pm.rest_time(10.0, 0.25)) == pytest.approx(40.9, abs=0.05)


@pytest.mark.parametrize("rpm,D", [(10.0, 0.25), (9.55, 0.25), (47.75, 0.25), (12.0, 0.05)])
def test_froude_mixing_rest_time_hand(rpm, D):
    Fr = hand_froude(rpm, D)
    N_mix = 16.0 * Fr**0.2  # [1.3]
    t_R = N_mix / (rpm / 60.0)  # [1.1]-[1.2]
    assert float(pm.froude(rpm, D)) == pytest.approx(Fr, rel=1e-13)
    assert float(pm.mixing_number(rpm, D)) == pytest.approx(N_mix, rel=1e-13)
    assert float(pm.rest_time(rpm, D)) == pytest.approx(t_R, rel=1e-12)
    # other constants
    assert float(pm.mixing_number(rpm, D, C=10.0, x=0.3)) == pytest.approx(10 * Fr**0.3, rel=1e-13)
    assert float(pm.rest_time(rpm, D, C=10.0, x=0.3)) == pytest.approx(10 * Fr**0.3 * 60 / rpm, rel=1e-12)


def test_omega_1_rad_per_s():
    # section 11.2: 9.55 rpm is omega = 1 rad/s -> Fr = omega^2 (D/2) / g = 0.125/9.81
    assert float(pm.froude(60.0 / (2 * math.pi), 0.25)) == pytest.approx(0.125 / 9.81, rel=1e-13)


def test_rest_time_resting_drum_is_infinite_and_arrays_broadcast():
    assert math.isinf(float(pm.rest_time(0.0, 0.25)))
    rpm = np.array([5.0, 10.0, 20.0])
    got = np.asarray(pm.rest_time(rpm, 0.25))
    want = [16 * hand_froude(r, 0.25) ** 0.2 * 60 / r for r in rpm]
    np.testing.assert_allclose(got, want, rtol=1e-12)
    # t_R ~ n^(2x - 1) = n^-0.6
    assert got[0] / got[1] == pytest.approx(2.0**0.6, rel=1e-12)


# --- coefficients ------------------------------------------------------------------------------


def test_alpha_wall_bed():
    # [1.7] alpha_ws = Phi alpha_wp
    assert float(pm.alpha_wall_bed(114.0)) == pytest.approx(0.8 * 114.0, rel=1e-15)
    assert float(pm.alpha_wall_bed(114.0, phi=math.pi / 4)) == pytest.approx(89.535390, rel=1e-7)


def test_alpha_bed_hand_value():
    # rho c lambda = 1230 * 836 * 0.9 = 925452; / 40 = 23136.3; sqrt = 152.1062;
    # * 2/sqrt(pi) = 1.1283792 -> 171.633
    got = float(pm.alpha_bed(0.9, 1230.0, 836.0, 40.0))
    assert got == pytest.approx(171.633, abs=1e-3)
    assert got == pytest.approx(hand_alpha_bed(0.9, 1230.0, 836.0, 40.0), rel=1e-14)


def test_instantaneous_is_half_of_mean_at_t_R_and_averages_to_mean():
    lam, rho, c, t_R = 0.9, 1274.0, 836.0, 40.0
    inst = float(pm.alpha_bed_instantaneous(lam, rho, c, t_R))
    # [1.11] alpha_bed,t = 1/sqrt(pi) sqrt(rho c lambda / t)
    assert inst == pytest.approx(math.sqrt(rho * c * lam / t_R) / math.sqrt(math.pi), rel=1e-14)
    assert float(pm.alpha_bed(lam, rho, c, t_R)) == pytest.approx(2 * inst, rel=1e-14)
    # time average of [1.11] over [0, t_R] equals [1.12] (digest item 12.12)
    integral, _ = quad(lambda t: float(pm.alpha_bed_instantaneous(lam, rho, c, t)), 0.0, t_R)
    assert integral / t_R == pytest.approx(float(pm.alpha_bed(lam, rho, c, t_R)), rel=1e-8)


def test_alpha_overall_series_hand_value():
    lam, rho, c = 0.9, 1274.0, 836.0
    t_R = 16 * hand_froude(10.0, 0.25) ** 0.2 * 6.0
    a_bed = hand_alpha_bed(lam, rho, c, t_R)
    a_ws = 0.8 * 114.0
    want = 1.0 / (1.0 / a_ws + 1.0 / a_bed)  # [1.6]
    got = float(pm.alpha_overall(114.0, lam, rho, c, pm.rest_time(10.0, 0.25)))
    assert got == pytest.approx(want, rel=1e-12)
    # series resistance: below both partial coefficients
    assert got < a_ws and got < a_bed
    # phi=1 is the A7 script convention (alpha_ws = alpha_wp)
    got1 = float(pm.alpha_overall(114.0, lam, rho, c, t_R, phi=1.0))
    assert got1 == pytest.approx(1.0 / (1.0 / 114.0 + 1.0 / a_bed), rel=1e-12)


def test_mean_temperature_closed_form():
    # [1.10] T = T_w - (T_w - T_0) exp(-alpha A t / (m c))
    m, c, A, alpha = 10.0, 836.0, 0.025, 80.0
    tau = m * c / (alpha * A)  # 4180 s
    t = np.array([0.0, 100.0, tau, 5 * tau])
    got = np.asarray(pm.mean_temperature(t, 343.0, 293.0, alpha, A, m, c))
    want = [343.0 - 50.0 * math.exp(-ti / tau) for ti in t]
    np.testing.assert_allclose(got, want, rtol=0, atol=1e-11)
    assert got[0] == 293.0
    assert got[2] == pytest.approx(343.0 - 50.0 / math.e, abs=1e-11)
    # cooling
    cool = float(pm.mean_temperature(tau, 293.0, 343.0, alpha, A, m, c))
    assert cool == pytest.approx(293.0 + 50.0 / math.e, abs=1e-11)


def test_mean_temperature_satisfies_balance_ode():
    # [1.9] m c dT/dt = alpha A (T_w - T), checked with jax derivative in t
    m, c, A, alpha, Tw = 3.0, 900.0, 0.01, 150.0, 350.0
    dTdt = jax.grad(lambda t: pm.mean_temperature(t, Tw, 300.0, alpha, A, m, c))
    for t in (0.0, 50.0, 2000.0):
        T = float(pm.mean_temperature(t, Tw, 300.0, alpha, A, m, c))
        assert m * c * float(dTdt(t)) == pytest.approx(alpha * A * (Tw - T), rel=1e-12)


# --- inverse relations ------------------------------------------------------------------------


@pytest.mark.parametrize("lam", [0.1, 0.9, 3.0])
def test_lambda_alpha_round_trip(lam):
    rho, c, t_R = 1274.0, 836.0, 40.86
    a = pm.alpha_bed(lam, rho, c, t_R)
    # [5.1] lambda = alpha^2 pi t / (4 rho c)
    assert float(pm.lambda_bed_from_alpha_bed(a, t_R, rho, c)) == pytest.approx(lam, rel=1e-13)
    # [5.3] t_th = 4 rho c lambda / (pi alpha^2) gives back t_R
    assert float(pm.thermal_mixing_time(a, rho, c, lam)) == pytest.approx(t_R, rel=1e-13)


def test_lambda_bed_from_alpha_bed_hand_value():
    # alpha = 100, t = 700 s, rho = 1230, c = 836: 1e4 * pi * 700 / (4 * 1230 * 836)
    want = 1e4 * math.pi * 700 / (4 * 1230 * 836)
    assert want == pytest.approx(5.3466, abs=1e-4)
    assert float(pm.lambda_bed_from_alpha_bed(100.0, 700.0, 1230.0, 836.0)) == pytest.approx(want, rel=1e-14)


def test_thermal_mixing_time_hand_value():
    # 4 * 1274 * 836 * 0.9 / (pi * 150^2)
    want = 4 * 1274 * 836 * 0.9 / (math.pi * 150.0**2)
    assert float(pm.thermal_mixing_time(150.0, 1274.0, 836.0, 0.9)) == pytest.approx(want, rel=1e-14)


# --- differentiability ------------------------------------------------------------------------


def test_grad_alpha_overall_wrt_lambda_bed_matches_finite_difference():
    args = dict(alpha_wp=114.0, rho_bed=1274.0, c_bed=836.0, t_R=40.86, phi=0.8)

    def f(lam):
        return pm.alpha_overall(args["alpha_wp"], lam, args["rho_bed"], args["c_bed"], args["t_R"], args["phi"])

    for lam in (0.3, 0.9, 2.0):
        g = float(jax.grad(f)(lam))
        h = 1e-5 * lam
        fd = (float(f(lam + h)) - float(f(lam - h))) / (2 * h)
        assert g == pytest.approx(fd, rel=1e-7)
        # analytic: d alpha/d lam = alpha^2 / alpha_bed^2 * d alpha_bed/d lam = alpha^2/(2 lam alpha_bed)
        a = float(f(lam))
        ab = float(pm.alpha_bed(lam, 1274.0, 836.0, 40.86))
        assert g == pytest.approx(a**2 / (2 * lam * ab), rel=1e-12)


def test_grad_through_rest_time_and_mean_temperature():
    # gradient of a PM mean temperature w.r.t. rpm, vs finite differences
    def T_end(rpm):
        t_R = pm.rest_time(rpm, 0.25)
        a = pm.alpha_overall(114.0, 0.9, 1274.0, 836.0, t_R)
        # A = d_p^2 N_w = 0.008^2 * 40 m^2, m = 370 glass spheres of 8 mm (6.7e-4 kg each)
        return pm.mean_temperature(1000.0, 343.0, 293.0, a, 0.008**2 * 40, 370 * 6.7e-4, 836.0)

    g = float(jax.grad(T_end)(10.0))
    h = 1e-4
    fd = (float(T_end(10.0 + h)) - float(T_end(10.0 - h))) / (2 * h)
    assert g > 0  # faster rotation -> shorter rest time -> larger alpha -> warmer bed
    assert g == pytest.approx(fd, rel=1e-6)


def test_vmap_over_parameters():
    lam = jnp.linspace(0.2, 2.0, 5)
    got = jax.vmap(lambda l: pm.alpha_overall(114.0, l, 1274.0, 836.0, 40.0))(lam)
    want = [1 / (1 / 91.2 + 1 / hand_alpha_bed(float(l), 1274.0, 836.0, 40.0)) for l in lam]
    np.testing.assert_allclose(np.asarray(got), want, rtol=1e-12)

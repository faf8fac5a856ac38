"""Tests of the heat-transfer analysis and observables, drumheat/observe.py.

Reference values are written out by hand from reference/weigler-thermal-dem.md (eq. numbers
in the comments) or come from analytic curves constructed for the purpose.
"""

import math

import jax
import jax.numpy as jnp
import numpy as np
import pytest
from scipy.special import erf

import drumheat  # noqa: F401  (enables float64)
from drumheat.results import observe as ob
from drumheat.models import penetration as pm

# Ch. 5.2 glass bed (digest sections 6.4, 10): 370 spheres of 8 mm, 40 wall contacts
D_P = 0.008
N_P = 370
N_W = 40
RHO_P, C_P = 2500.0, 836.0
M_C = N_P * RHO_P * math.pi * D_P**3 / 6 * C_P  # J/K
AREA = D_P**2 * N_W  # m^2, A7 convention
T0, TW = 293.0, 343.0


# --- alpha_overall [1.10] ---------------------------------------------------------------------


@pytest.mark.parametrize("alpha,T_0,T_w", [(60.0, 293.0, 343.0), (250.0, 293.0, 343.0), (80.0, 323.15, 298.15)])
def test_alpha_overall_recovers_constant_alpha(alpha, T_0, T_w):
    # up to 15 time constants: beyond that T_w - T_mean nears the float64 resolution of T_w
    # (exp(-15) * 50 K ~ 1.5e-5 K >> 343 K * 2.2e-16) and the logarithm loses accuracy
    t_end = 15 * M_C / (alpha * AREA)
    t = np.concatenate([[0.0], np.logspace(0, math.log10(t_end), 50)])
    T_mean = pm.mean_temperature(t, T_w, T_0, alpha, AREA, M_C / C_P, C_P)
    got = np.asarray(ob.alpha_overall(t, T_mean, T_w, T_0, M_C, AREA))
    assert math.isnan(got[0])  # t = 0: 0/0, digest item 12.13
    np.testing.assert_allclose(got[1:], alpha, rtol=1e-9)


def test_alpha_overall_hand_value():
    # m c = 1000 J/K, A = 0.01 m^2, t = 100 s, T_w - T_0 = 50 K, T_w - T_mean = 25 K:
    # alpha = 1000/(0.01*100) * ln 2 = 1000 ln 2
    got = float(ob.alpha_overall(100.0, 318.0, 343.0, 293.0, 1000.0, 0.01))
    assert got == pytest.approx(1000 * math.log(2), rel=1e-14)
    # T_mean beyond the wall temperature: no real log -> NaN, not a silent number
    assert math.isnan(float(ob.alpha_overall(100.0, 344.0, 343.0, 293.0, 1000.0, 0.01)))


def test_alpha_overall_gradient_is_finite_next_to_t0():
    t = jnp.array([0.0, 10.0, 100.0])

    def f(T_mean):
        return jnp.nansum(ob.alpha_overall(t, T_mean, TW, T0, M_C, AREA))

    g = np.asarray(jax.grad(f)(jnp.array([293.0, 295.0, 300.0])))
    assert g[0] == 0.0 and np.all(np.isfinite(g))
    # d alpha / d T_mean = m c / (A t) / (T_w - T_mean)
    assert g[1] == pytest.approx(M_C / (AREA * 10.0) / (TW - 295.0), rel=1e-12)


def test_grad_of_observed_alpha_wrt_true_alpha_is_one():
    t = 500.0

    def f(alpha):
        T_mean = pm.mean_temperature(t, TW, T0, alpha, AREA, M_C / C_P, C_P)
        return ob.alpha_overall(t, T_mean, TW, T0, M_C, AREA)

    assert float(jax.grad(f)(75.0)) == pytest.approx(1.0, rel=1e-9)


# --- alpha_bed_from_overall [1.6], lambda_bed_curve [5.1] ------------------------------------


def test_alpha_bed_from_overall_hand_value_and_invalid():
    # 1/(1/50 - 1/91.2) = 50 * 91.2 / 41.2
    assert float(ob.alpha_bed_from_overall(50.0, 91.2)) == pytest.approx(50 * 91.2 / 41.2, rel=1e-14)
    got = np.asarray(ob.alpha_bed_from_overall(np.array([91.2, 100.0, np.nan]), 91.2))
    assert np.all(np.isnan(got))


def test_a7_pipeline_recovers_pm_alpha_bed_and_lambda():
    # analytic PM curve (A8): alpha_PM from [1.6], [1.7], [1.12]; back-calculation gives
    # alpha_bed and, at t = t_R, lambda_bed back
    lam, rho_bed, t_R, alpha_wp = 0.9, 1274.0, 40.0, 114.0
    a_pm = pm.alpha_overall(alpha_wp, lam, rho_bed, C_P, t_R)
    t = np.linspace(0.0, 2000.0, 51)
    T_mean = pm.mean_temperature(t, TW, T0, a_pm, AREA, M_C / C_P, C_P)
    alpha = ob.alpha_overall(t, T_mean, TW, T0, M_C, AREA)
    a_bed = ob.alpha_bed_from_overall(alpha, pm.alpha_wall_bed(alpha_wp))
    want = 2 / math.sqrt(math.pi) * math.sqrt(rho_bed * C_P * lam / t_R)
    np.testing.assert_allclose(np.asarray(a_bed)[1:], want, rtol=1e-8)
    lam_curve = np.asarray(ob.lambda_bed_curve(np.full_like(t, t_R), a_bed, rho_bed, C_P))
    np.testing.assert_allclose(lam_curve[1:], lam, rtol=1e-8)
    assert float(ob.thermal_mixing_time(want, rho_bed, C_P, lam)) == pytest.approx(t_R, rel=1e-13)


def test_lambda_bed_curve_hand_value():
    t = np.array([100.0, 700.0])
    a_bed = np.array([200.0, 60.0])
    want = a_bed**2 * math.pi * t / (4 * 1230.0 * 836.0)  # [5.1]
    np.testing.assert_allclose(np.asarray(ob.lambda_bed_curve(t, a_bed, 1230.0, 836.0)), want, rtol=1e-14)
    # 60^2 * pi * 700 / (4 * 1230 * 836) = 1.9248
    assert want[1] == pytest.approx(1.9248, abs=1e-4)


# --- log_slope -------------------------------------------------------------------------------


def test_log_slope_power_law_nonuniform_grid():
    rng = np.random.default_rng(0)
    t = np.sort(rng.uniform(1.0, 1e4, 80))
    y = 7.0 * t**-0.5
    np.testing.assert_allclose(ob.log_slope(t, y), -0.5, atol=1e-12)
    np.testing.assert_allclose(ob.log_slope(t, y, smooth=0.2), -0.5, atol=1e-12)


def test_log_slope_quadratic_in_log_is_exact():
    # ln y = 0.1 (ln t)^2 -> slope 0.2 ln t; 3-point non-uniform formulas are exact
    t = np.array([1.0, 1.5, 3.0, 4.0, 10.0, 11.0, 50.0, 300.0])
    y = np.exp(0.1 * np.log(t) ** 2)
    np.testing.assert_allclose(ob.log_slope(t, y), 0.2 * np.log(t), atol=1e-12)


def test_log_slope_skips_invalid_points():
    t = np.array([0.0, 1.0, 2.0, 4.0, 8.0, 16.0])
    y = 3.0 / np.sqrt(np.maximum(t, 1e-300))
    y[0] = np.nan  # what alpha_overall returns at t = 0
    y[3] = np.nan
    s = ob.log_slope(t, y)
    assert np.isnan(s[0]) and np.isnan(s[3])
    np.testing.assert_allclose(s[[1, 2, 4, 5]], -0.5, atol=1e-12)


def test_log_slope_smoothing_reduces_noise():
    rng = np.random.default_rng(1)
    t = np.logspace(0, 4, 400)
    y = t**-0.3 * (1 + 0.01 * rng.standard_normal(t.size))
    raw = ob.log_slope(t, y)
    sm = ob.log_slope(t, y, smooth=0.2)
    assert np.std(raw + 0.3) > 0.1
    assert np.max(np.abs(sm[50:-50] + 0.3)) < 0.02


# --- penetration_time ------------------------------------------------------------------------


def test_penetration_time_slope_criterion():
    # alpha = a0 / (1 + t/t0): slope = -(t/t0)/(1 + t/t0) = -0.5 exactly at t = t0
    t0 = 321.0
    t = np.concatenate([[0.0], np.logspace(0, 4, 150)])
    alpha = 120.0 / (1 + t / t0)
    alpha[0] = np.nan
    res = ob.penetration_time(t, alpha)
    assert res.criterion == "slope"
    assert res.time == pytest.approx(t0, rel=1e-4)
    assert res.slope_at_time == -0.5
    assert res.slope.shape == t.shape


def gaussian_slope_curve(t, amplitude, x0, w, a0=100.0):
    # ln alpha with slope d ln alpha / d ln t = -amplitude exp(-(ln t - x0)^2 / (2 w^2))
    x = np.log(t)
    return a0 * np.exp(-amplitude * w * math.sqrt(math.pi / 2) * erf((x - x0) / (w * math.sqrt(2))))


def test_penetration_time_inflection_when_slope_stays_above_target():
    # slope minimum -0.3 at t = 700 s (the thesis' cylinder packings, section 10 step 4)
    t = np.logspace(0, 4, 200)
    alpha = gaussian_slope_curve(t, 0.3, math.log(700.0), 1.0)
    s = ob.log_slope(t, alpha)
    np.testing.assert_allclose(s, -0.3 * np.exp(-((np.log(t) - math.log(700)) ** 2) / 2), atol=2e-3)
    res = ob.penetration_time(t, alpha)
    assert res.criterion == "inflection"
    assert res.time == pytest.approx(700.0, rel=1e-3)
    assert res.slope_at_time == pytest.approx(-0.3, abs=1e-3)
    res_s = ob.penetration_time(t, alpha, smooth=0.1)
    assert res_s.criterion == "inflection"
    assert res_s.time == pytest.approx(700.0, rel=1e-2)
    none = ob.penetration_time(t, alpha, fallback=False)
    assert none.criterion == "none" and math.isnan(none.time)


def test_penetration_time_first_and_last_crossing():
    # slope minimum -0.8 at x0: crossings of -0.5 at x0 -/+ w sqrt(2 ln(0.8/0.5))
    x0, w = math.log(500.0), 0.8
    t = np.logspace(0, 4.5, 400)
    alpha = gaussian_slope_curve(t, 0.8, x0, w)
    dx = w * math.sqrt(2 * math.log(0.8 / 0.5))
    first = ob.penetration_time(t, alpha)
    last = ob.penetration_time(t, alpha, which="last")
    assert first.criterion == last.criterion == "slope"
    assert first.time == pytest.approx(math.exp(x0 - dx), rel=2e-3)
    assert last.time == pytest.approx(math.exp(x0 + dx), rel=2e-3)
    window = ob.penetration_time(t, alpha, t_range=(math.exp(x0), np.inf))
    assert window.time == pytest.approx(last.time, rel=1e-12)
    np.testing.assert_array_equal(window.slope, first.slope)


def test_penetration_time_monotone_slope_has_no_inflection():
    # slope falls monotonically from 0 to -0.3 (never -0.5): extremum at the end -> "none"
    t = np.logspace(0, 4, 100)
    alpha = 1.0 / (1 + t / 50.0) ** 0.3
    res = ob.penetration_time(t, alpha)
    assert res.criterion == "none" and math.isnan(res.time)


# --- calibration line ------------------------------------------------------------------------


def test_calibration_line_two_points_and_inverse():
    line = ob.calibration_line([57.0, 114.0], [0.9, 1.6])
    slope = (1.6 - 0.9) / (114.0 - 57.0)
    assert float(line.slope) == pytest.approx(slope, rel=1e-13)
    assert float(line.intercept) == pytest.approx(0.9 - slope * 57.0, rel=1e-12)
    assert float(line.lambda_bed(57.0)) == pytest.approx(0.9, rel=1e-13)
    assert float(line.alpha_pp(1.6)) == pytest.approx(114.0, rel=1e-13)
    x = np.array([10.0, 80.0, 300.0])
    np.testing.assert_allclose(np.asarray(line.alpha_pp(line.lambda_bed(x))), x, rtol=1e-13)


def test_calibration_line_through_origin_and_least_squares():
    # through the origin: a = sum(x y)/sum(x^2) = (57*0.9 + 114*1.9)/(57^2 + 114^2)
    line0 = ob.calibration_line([57.0, 114.0], [0.9, 1.9], through_origin=True)
    assert float(line0.slope) == pytest.approx((57 * 0.9 + 114 * 1.9) / (57**2 + 114**2), rel=1e-13)
    assert float(line0.intercept) == 0.0
    one = ob.calibration_line([57.0], [0.9], through_origin=True)
    assert float(one.lambda_bed(114.0)) == pytest.approx(1.8, rel=1e-13)
    rng = np.random.default_rng(2)
    x = np.linspace(20, 200, 9)
    y = 0.016 * x + 0.05 + 0.01 * rng.standard_normal(x.size)
    line = ob.calibration_line(x, y)
    b1, b0 = np.polyfit(x, y, 1)
    assert float(line.slope) == pytest.approx(b1, rel=1e-10)
    assert float(line.intercept) == pytest.approx(b0, rel=1e-8)
    with pytest.raises(ValueError, match="at least 2"):
        ob.calibration_line([57.0], [0.9])


def test_calibration_line_is_differentiable():
    # d lambda(alpha)/d lambda_2 for the two-point line = (alpha - x1)/(x2 - x1)
    def f(lam2):
        return ob.calibration_line(jnp.array([57.0, 114.0]), jnp.stack([0.9, lam2])).lambda_bed(80.0)

    assert float(jax.grad(f)(1.6)) == pytest.approx((80 - 57) / (114 - 57), rel=1e-12)


# --- group means and temperature distributions -------------------------------------------------


def test_group_means_hand_values():
    T = np.array([[300.0, 310.0, 320.0, 330.0], [301.0, 309.0, 321.0, 329.0]])
    m = np.array([1.0, 3.0, 2.0, 2.0])
    groups = np.array([0, 0, 1, 1])
    got = np.asarray(ob.group_means(T, m, groups))
    want = np.array([
        [(300 + 3 * 310) / 4, (2 * 320 + 2 * 330) / 4],
        [(301 + 3 * 309) / 4, (2 * 321 + 2 * 329) / 4],
    ])
    np.testing.assert_allclose(got, want, rtol=1e-14)
    single = np.asarray(ob.group_means(T[0], m, groups, n_groups=3))
    np.testing.assert_allclose(single[:2], want[0], rtol=1e-14)
    assert np.isnan(single[2])  # empty group


def test_group_means_gradient():
    m = jnp.array([1.0, 3.0])
    g = jax.grad(lambda T: ob.group_means(T, m, jnp.array([0, 0]), n_groups=1)[0])(jnp.array([300.0, 310.0]))
    np.testing.assert_allclose(np.asarray(g), [0.25, 0.75], rtol=1e-14)


def test_temperature_distribution_hand_values():
    T = np.array([298.2, 298.7, 299.1, 301.5])
    d = ob.temperature_distribution(T, width=1.0, T_lo=298.0, T_hi=302.0)
    np.testing.assert_allclose(d.edges, [298, 299, 300, 301, 302])
    np.testing.assert_allclose(d.centres, [298.5, 299.5, 300.5, 301.5])
    np.testing.assert_array_equal(d.counts, [2, 1, 0, 1])
    np.testing.assert_allclose(d.q0, [0.5, 0.25, 0.0, 0.25])  # 1/K
    np.testing.assert_allclose(d.Q0, [0.0, 0.5, 0.75, 0.75, 1.0])
    # default classes cover all particles; 2 K classes halve the density per K
    d2 = ob.temperature_distribution(T, width=2.0)
    np.testing.assert_allclose(d2.edges, [298, 300, 302])
    np.testing.assert_allclose(d2.q0, [0.75 / 2, 0.25 / 2])


def test_temperature_distribution_rows_and_out_of_range():
    T = np.array([[298.2, 298.7, 299.1, 301.5], [300.1, 300.2, 300.3, 300.4]])
    d = ob.temperature_distribution(T, t_index=[0, 1], T_lo=299.0, T_hi=301.0)
    np.testing.assert_array_equal(d.counts, [[1, 0], [0, 4]])
    np.testing.assert_allclose(d.Q0[0], [0.5, 0.75, 0.75])  # 2 below T_lo, 1 above T_hi
    assert d.q0[1].sum() * 1.0 == pytest.approx(1.0)  # integral of q0 over the classes
    d1 = ob.temperature_distribution(T, t_index=1)
    assert d1.q0.ndim == 1 and d1.counts.sum() == 4
    # a NaN temperature is not counted and does not enter N
    dn = ob.temperature_distribution(np.array([298.5, np.nan, 299.5, 299.6]), T_lo=298.0, T_hi=300.0)
    np.testing.assert_array_equal(dn.counts, [1, 2])
    np.testing.assert_allclose(dn.Q0, [0.0, 1 / 3, 1.0])
    with pytest.raises(ValueError, match="multiple of width"):
        ob.temperature_distribution(T, T_lo=299.0, T_hi=300.5)


# --- mixing index and contacts ----------------------------------------------------------------


def test_mixing_index_hand_value():
    # cells (unit size): A holds 3 (2 tracers), B holds 1 (0), C holds 2 (1).
    # p = 1/2, sigma0^2 = 1/4, sigmaR^2 = 1/4 * 3/6 = 1/8,
    # S^2 = (3 (2/3 - 1/2)^2 + (1/2)^2 + 0) / 6 = 1/18, M = (1/4 - 1/18)/(1/8) = 14/9
    pos = np.array([[0.1, 0.1], [0.5, 0.5], [0.9, 0.2], [1.5, 0.5], [0.5, 1.5], [0.2, 1.9]])
    tracer = np.array([1, 1, 0, 0, 1, 0], bool)
    assert ob.mixing_index(pos, tracer, 1.0, origin=[0.0, 0.0]) == pytest.approx(14 / 9, rel=1e-14)


def test_mixing_index_segregated_and_random():
    rng = np.random.default_rng(3)
    pos = rng.uniform(0, 1, (20000, 2))
    segregated = pos[:, 0] < 0.5
    assert ob.mixing_index(pos, segregated, 0.05, origin=[0.0, 0.0]) == pytest.approx(0.0, abs=1e-12)
    random = rng.uniform(size=20000) < 0.5
    assert ob.mixing_index(pos, random, 0.05, origin=[0.0, 0.0]) == pytest.approx(1.0, abs=0.02)
    both = ob.mixing_index(np.stack([pos, pos]), segregated, 0.05, origin=[0.0, 0.0])
    assert both.shape == (2,)


def test_count_interfraction_contacts():
    group = np.array([0, 0, 1, 1, 2])
    N = group.size
    pi = np.array([[0, 0, 1, 2, 3, N], [0, 1, 2, 3, 4, N]])
    pj = np.array([[1, 2, 3, 3, 4, N], [3, 2, 0, 4, 2, N]])
    mask = np.array([[1, 1, 1, 0, 1, 0], [1, 1, 1, 1, 1, 0]], bool)
    # row 0: (0,1) same, (0,2) diff, (1,3) diff, (2,3) masked, (3,4) diff -> 3
    # row 1: (0,3) diff, (1,2) diff, (2,0) diff, (3,4) diff, (4,2) diff -> 5
    np.testing.assert_array_equal(np.asarray(ob.count_interfraction_contacts(pi, pj, mask, group)), [3, 5])
    # only between groups 0 and 1: row 0 -> 2, row 1 -> 3
    np.testing.assert_array_equal(
        np.asarray(ob.count_interfraction_contacts(pi, pj, mask, group, fractions=(0, 1))), [2, 3]
    )
    # mask None: padding index N is excluded; (2,3) is same-group anyway -> 3 and 5
    np.testing.assert_array_equal(np.asarray(ob.count_interfraction_contacts(pi, pj, None, group)), [3, 5])


def test_mechanical_mixing_time_recovers_tau():
    rng = np.random.default_rng(4)
    tau, c0, cinf = 8.0, 5.0, 150.0
    t = np.linspace(0.0, 60.0, 121)
    counts = cinf - (cinf - c0) * np.exp(-t / tau) + 4.0 * rng.standard_normal(t.size)
    fit = ob.mechanical_mixing_time(t, counts)
    assert fit.tau == pytest.approx(tau, rel=0.05)
    assert abs(fit.tau - tau) < 4 * fit.tau_std
    assert fit.c_inf == pytest.approx(cinf, rel=0.02)
    assert fit.time == pytest.approx(fit.tau * math.log(20.0), rel=1e-14)  # 95 % of the rise
    assert fit.within_record
    np.testing.assert_allclose(fit.trend(np.array([0.0])), [fit.c_0])
    # a record too short for the plateau is flagged
    short = ob.mechanical_mixing_time(t[:25], counts[:25], plateau_fraction=0.99)
    assert not short.within_record


def test_mixing_time_horizontal_finds_the_break_of_a_ramp_and_plateau():
    from drumheat.results.observe import mixing_time_horizontal

    rng = np.random.default_rng(0)
    t = np.arange(0.0, 180.0, 0.5)
    c = 20.0 + 1.5 * np.minimum(t, 48.0) + rng.normal(0.0, 2.0, t.size)
    fit = mixing_time_horizontal(t, c)
    assert fit.time == pytest.approx(48.0, abs=2.0)
    assert fit.plateau == pytest.approx(92.0, abs=1.0)
    assert fit.slope == pytest.approx(1.5, rel=0.05)
    assert fit.within_record and fit.residual == pytest.approx(2.0, rel=0.15)
    # a record that never levels off: the break sits at its end
    assert not mixing_time_horizontal(t, 20.0 + 1.5 * t).within_record

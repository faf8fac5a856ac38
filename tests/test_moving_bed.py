"""Tests of the Kraychev moving-bed / tube-bundle models (reference/kraychev-tube-bundle.md)."""

import math

import numpy as np
import pytest

import drumheat  # noqa: F401
from drumheat.models import drag
from drumheat.models import moving_bed as mb


# ---------------------------------------------------------------------------------------------
# hopper discharge, eqs. (5-3)..(5-6)
# ---------------------------------------------------------------------------------------------


def test_discharge_velocity_millet_hand_value():
    # millet d_p = 1.65 mm: gamma = 8.2 (1.65 - 1.65) = 0 deg (5-4)
    # W_p = 0.01 tan(58 deg) (4/1.65 - 1.1) = 0.01 * 1.600335 * 1.324242 = 0.0211923 m/s (5-5)
    W = float(mb.discharge_velocity(4e-3, 1.65e-3))
    assert W == pytest.approx(0.01 * math.tan(math.radians(58.0)) * (4 / 1.65 - 1.1), rel=1e-13)
    assert W == pytest.approx(0.0211923, rel=1e-5)
    assert float(mb.discharge_repose_angle_deg(1.65e-3)) == pytest.approx(0.0, abs=1e-12)


def test_discharge_velocity_wheat_with_secondary_gas():
    # wheat d_p = 4.07 mm, S = 12 mm: gamma = 8.2 * 2.42 = 19.844 deg
    # W_p0 = 0.01 tan(77.844 deg) (12/4.07 - 1.1) = 0.01 * 4.64244 * 1.84840 = 0.085811 m/s
    # (5-6): + 0.008 W_SG + 0.04 W_SG^2 + 0.95 W_SG^3 with W_SG = 0.132 m/s (+0.0039384 m/s)
    W0 = 0.01 * math.tan(math.radians(58.0 + 8.2 * (4.07 - 1.65))) * (12 / 4.07 - 1.1)
    assert float(mb.discharge_velocity(12e-3, 4.07e-3)) == pytest.approx(W0, rel=1e-13)
    assert W0 == pytest.approx(0.085811, rel=1e-5)
    Wsg = 0.132
    W = float(mb.discharge_velocity(12e-3, 4.07e-3, W_SG=Wsg))
    assert W == pytest.approx(W0 + 0.008 * Wsg + 0.04 * Wsg**2 + 0.95 * Wsg**3, rel=1e-13)
    assert W - W0 == pytest.approx(0.0039379, rel=1e-4)


def test_discharge_velocity_limits_and_ranges():
    # W_p = 0 at S/d_p = 1.1; a narrower slit jams (0, not a negative velocity)
    assert float(mb.discharge_velocity(1.1 * 2e-3, 2e-3)) == pytest.approx(0.0, abs=1e-15)
    assert float(mb.discharge_velocity(1.0 * 2e-3, 2e-3)) == 0.0
    # monotone in S and in W_SG
    S = np.linspace(4e-3, 16e-3, 5)
    assert np.all(np.diff(np.asarray(mb.discharge_velocity(S, 3e-3))) > 0)
    with pytest.raises(ValueError, match="d_p"):
        mb.discharge_velocity(12e-3, 6e-3)
    with pytest.raises(ValueError, match="W_SG"):
        mb.discharge_velocity(12e-3, 3e-3, W_SG=0.2)
    # extrapolation: the tangent argument is clamped at d_p = 5 mm (digest Sec. 7)
    W6 = float(mb.discharge_velocity(18e-3, 6e-3, check=False))
    assert W6 == pytest.approx(0.01 * math.tan(math.radians(58 + 8.2 * 3.35)) * (3 - 1.1))


def test_senkov_hydraulic_radius_cpp_example():
    # (A - a')(s - a') / [2 (A + s - 2 a')], a' = 1.4 d_p; millet, s = 4 mm, A = 500 mm:
    # (0.5 - 0.00231)(0.004 - 0.00231) / [2 (0.504 - 0.00462)] = 0.842 mm (C++ input: 0.84 mm)
    R_h = float(mb.senkov_hydraulic_radius(0.5, 4e-3, 1.65e-3))
    a = 1.4 * 1.65e-3
    assert R_h == pytest.approx((0.5 - a) * (4e-3 - a) / (2 * (0.5 + 4e-3 - 2 * a)), rel=1e-14)
    assert R_h == pytest.approx(0.84e-3, abs=0.005e-3)


# ---------------------------------------------------------------------------------------------
# tube bundle -> moving bed, eqs. (5-16)..(5-19)
# ---------------------------------------------------------------------------------------------


def test_effective_conductivity():
    # lambda* = 0.59 lambda_M + 0.41 lambda_G (5-17) = 0.59*0.2 + 0.41*0.026 = 0.12866
    assert float(mb.effective_conductivity(0.2, 0.026)) == pytest.approx(0.12866, rel=1e-13)


def test_peclet_and_nusselt_hand_values():
    d_p, rho_M, c_pM, lam_M = 1.43e-3, 1500.0, 800.0, 0.2  # sand (Pascal example data)
    W_p, W_SG, rho_G, c_pG = 0.02, 0.066, 1.2, 1005.0
    lam = 0.59 * lam_M + 0.41 * 0.026
    # Pe* = [rho_G c_pG 0.41 W_SG + rho_M c_pM 0.59 W_p] d_p / lambda*
    #     = [1.2*1005*0.41*0.066 + 1500*800*0.59*0.02] * 1.43e-3 / 0.12866
    #     = [32.634 + 14160] * 0.011115 = 157.74
    pe = float(mb.peclet_star(W_p, d_p, rho_M, c_pM, lam, W_SG=W_SG, rho_G=rho_G, c_pG=c_pG))
    expect_pe = (rho_G * c_pG * 0.41 * W_SG + rho_M * c_pM * 0.59 * W_p) * d_p / lam
    assert pe == pytest.approx(expect_pe, rel=1e-13)
    assert pe == pytest.approx(157.74, rel=1e-4)
    # Nu_1 = 0.155 Pe*^0.22 (D_R/d_p)^0.33 = 0.155 * 157.74^0.22 * 9.7902^0.33
    #      = 0.155 * 3.04474 * 2.12306 = 1.00194   (sand: the upper end D_R/d_p = 14/1.43)
    nu = float(mb.nusselt_tube_bundle(pe, 0.014, d_p))
    assert nu == pytest.approx(0.155 * pe**0.22 * (0.014 / d_p) ** 0.33, rel=1e-13)
    assert nu == pytest.approx(1.00194, rel=1e-5)
    # alpha_1 = Nu_1 lambda* / d_p (5-16), chained
    alpha = float(mb.alpha_tube_bundle(1.5e-3, rho_M, c_pM, lam_M, W_p, W_SG=W_SG))
    pe2 = (1.2 * 1005 * 0.41 * W_SG + rho_M * c_pM * 0.59 * W_p) * 1.5e-3 / lam
    assert alpha == pytest.approx(0.155 * pe2**0.22 * (0.014 / 1.5e-3) ** 0.33 * lam / 1.5e-3,
                                  rel=1e-13)


def test_nusselt_validity_and_table_coefficients():
    with pytest.raises(ValueError, match="Pe"):
        mb.nusselt_tube_bundle(30.0, 0.014, 3e-3)
    with pytest.raises(ValueError, match="D_R/d_p"):
        mb.nusselt_tube_bundle(300.0, 0.014, 1e-3)  # D_R/d_p = 14 > 9.79
    # Table 5.2.1 alternatives are not range-checked
    v = float(mb.nusselt_tube_bundle(300.0, 0.014, 3e-3, coefficients="kalenderjan_grains"))
    assert v == pytest.approx(0.79 * 300**0.28 * (0.014 / 3e-3) ** 0.404)


# ---------------------------------------------------------------------------------------------
# channel coefficient alpha_2 (Sec. 6)
# ---------------------------------------------------------------------------------------------


def test_channel_alpha2_evaluation_appendix_inputs():
    """Appendix 10.4 inputs (wheat); the temperatures are illustrative (the source's are
    withheld), so only the arithmetic of Sec. 6 steps 1-4 is checked."""
    d_p, rho_M = 4.07e-3, 1315.0
    m_L, c_pL, rho_L, lam_L = 0.170, 1005.0, 1.16, 0.0267
    L_App, S, beta, V = 0.487, 12e-3, 0.6, 0.180
    W_p = float(mb.discharge_velocity(S, d_p))  # 5-5, not the printed value (erratum)
    m_circ = float(mb.circulating_solids_flow(L_App, S, W_p, rho_M, beta))
    # (8-5): L S W_p beta rho_M = 0.487 * 0.012 * 0.085811 * 0.6 * 1315 = 0.39567 kg/s
    assert m_circ == pytest.approx(L_App * S * W_p * beta * rho_M, rel=1e-13)
    assert m_circ == pytest.approx(0.39567, rel=1e-4)
    T_L1, T_L2, t_M1, t_M2 = 20.0, 30.0, 70.0, 45.0
    ev = mb.channel_alpha2(m_L=m_L, c_pL=c_pL, T_L1=T_L1, T_L2=T_L2, t_M1=t_M1, t_M2=t_M2,
                           m_solids=m_circ, V=V, rho_G=rho_L, rho_M=rho_M, d_p=d_p,
                           lambda_G=lam_L)
    Q = m_L * c_pL * (T_L2 - T_L1)  # 1708.5 W
    dt = ((t_M1 - T_L1) - (t_M2 - T_L2)) / math.log((t_M1 - T_L1) / (t_M2 - T_L2))  # 29.07 K
    A = (m_circ / m_L) * V * rho_L * 6 / (rho_M * d_p)  # mu_2 V rho sigma_M
    assert float(ev.Q_2) == pytest.approx(1708.5, rel=1e-13)
    assert float(ev.dt_ln) == pytest.approx(dt, rel=1e-13)
    assert float(ev.dt_ln) == pytest.approx(35.0 / math.log(50.0 / 15.0), rel=1e-13)
    assert float(ev.A_Sch2) == pytest.approx(A, rel=1e-13)
    assert float(ev.alpha_2) == pytest.approx(Q / (A * dt), rel=1e-13)
    assert float(ev.Nu_2) == pytest.approx(Q / (A * dt) * d_p / lam_L, rel=1e-13)
    assert float(mb.specific_surface(1315.0, 4.07e-3)) == pytest.approx(6 / (1315 * 4.07e-3))


def test_lmtd_equal_differences():
    assert float(mb.lmtd(10.0, 10.0)) == pytest.approx(10.0)
    assert float(mb.lmtd(10.0, 10.0 * (1 + 1e-6))) == pytest.approx(10.000005, rel=1e-9)
    assert float(mb.lmtd(40.0, 10.0)) == pytest.approx(30.0 / math.log(4.0))


def test_gnielinski_sphere():
    Re, Pr = 1000.0, 0.7
    # Nu_lam = 0.664 * 31.623 * 0.8879 = 18.64; Nu_turb = 6.506 / 0.7409 = 8.78; Nu = 22.61
    lam = 0.664 * Re**0.5 * Pr ** (1 / 3)
    turb = 0.037 * Re**0.8 * Pr / (1 + 2.443 * Re**-0.1 * (Pr ** (2 / 3) - 1))
    nu = float(mb.nusselt_sphere_gnielinski(Re, Pr))
    assert nu == pytest.approx(2 + math.sqrt(lam**2 + turb**2), rel=1e-13)
    assert nu == pytest.approx(22.61, rel=1e-3)
    assert float(mb.nusselt_sphere_gnielinski(1e-12, 0.7)) == pytest.approx(2.0, abs=1e-5)
    tab = float(mb.nusselt_sphere_gnielinski(Re, Pr, variant="source_tables"))
    turb_t = 0.037 * Re**0.8 * Pr / (1 + 2.443 * Re**-0.3 * (Pr**0.66 - 1))
    assert tab == pytest.approx(2 + math.sqrt((0.664 * Re**0.5 * Pr**0.33) ** 2 + turb_t**2))


# ---------------------------------------------------------------------------------------------
# terminal velocity (Sec. 10) and eq. (3-13)
# ---------------------------------------------------------------------------------------------


def test_terminal_velocity_regimes_hand_values():
    # Newton (3-89): 5.2 sqrt(d rho_M / rho_G) = 5.2 * sqrt(4.07e-3 * 1315 / 1.2) = 10.982 m/s
    tv = mb.terminal_velocity_kraychev(4.07e-3, 1315.0, 1.2, 1.5e-5)
    assert tv.regime == "newton"
    assert tv.W == pytest.approx(5.2 * math.sqrt(4.07e-3 * 1315 / 1.2), rel=1e-14)
    assert tv.W == pytest.approx(10.982, rel=1e-4)
    # intermediate (3-88): 39 d rho^0.67 = 39 * 0.5e-3 * 2500^0.67 = 3.687 m/s (Re = 123)
    tv = mb.terminal_velocity_kraychev(0.5e-3, 2500.0, 1.2, 1.5e-5)
    assert tv.regime == "intermediate"
    assert tv.W == pytest.approx(39 * 0.5e-3 * 2500**0.67, rel=1e-14)
    # Stokes (3-87): g d^2 rho_M / (18 nu rho_G) = 9.80665 * 4e-10 * 2500 / 3.24e-4 = 0.030267
    tv = mb.terminal_velocity_kraychev(20e-6, 2500.0, 1.2, 1.5e-5)
    assert tv.regime == "stokes"
    assert tv.W == pytest.approx(drag.G * 20e-6**2 * 2500 / (18 * 1.5e-5 * 1.2), rel=1e-14)
    with pytest.raises(ValueError, match="between 1 and 10"):
        mb.terminal_velocity_kraychev(0.1e-3, 2500.0, 1.2, 1.5e-5)


def test_terminal_velocity_fits_match_drag_laws():
    # 3-89's coefficient is Newton drag with C_D = 0.48: sqrt(4 g / (3 * 0.48)) = 5.227
    assert math.sqrt(4 * drag.G / (3 * 0.48)) == pytest.approx(5.2, rel=0.006)
    # 3-87 is Stokes' law without buoyancy
    d, rho_M, rho_G, nu = 20e-6, 2500.0, 1.2, 1.5e-5
    W_stokes = float(drag.terminal_velocity(d, rho_M, rho_G, nu * rho_G, drag_law="stokes"))
    assert mb.terminal_velocity_kraychev(d, rho_M, rho_G, nu).W == pytest.approx(
        W_stokes * rho_M / (rho_M - rho_G), rel=1e-10)
    # the regime fits agree with a Schiller-Naumann solution to within 15 % for the materials
    for d, rho in ((0.5e-3, 2500.0), (1.65e-3, 1250.0), (4.07e-3, 1315.0), (20e-6, 2500.0)):
        W_fit = mb.terminal_velocity_kraychev(d, rho, 1.2, 1.5e-5).W
        W_sn = float(drag.terminal_velocity(d, rho, 1.2, 1.5e-5 * 1.2))
        assert W_fit == pytest.approx(W_sn, rel=0.15), (d, rho)


def test_terminal_reynolds_archimedes():
    # Re = 18 [sqrt(1 + sqrt(Ar)/9) - 1]^2 -> Ar/18 (Stokes) and -> 2 sqrt(Ar) (C_D -> 1/3)
    assert float(mb.reynolds_terminal_archimedes(1e-6)) == pytest.approx(1e-6 / 18, rel=1e-3)
    Ar = 1e9
    assert float(mb.reynolds_terminal_archimedes(Ar)) == pytest.approx(
        18 * (math.sqrt(1 + math.sqrt(Ar) / 9) - 1) ** 2, rel=1e-14)
    assert float(mb.reynolds_terminal_archimedes(1e16)) / (2 * 1e8) == pytest.approx(1, rel=1e-3)
    # Ar = g d^3 (rho_p - rho_G)/(nu^2 rho_G)
    assert float(mb.archimedes_kraychev(1e-3, 2500.0, 1.2, 1.5e-5)) == pytest.approx(
        drag.G * 1e-9 * 2498.8 / (2.25e-10 * 1.2))
    assert float(mb.design_channel_velocity(10.0)) == 15.0


# ---------------------------------------------------------------------------------------------
# pressure drop (Sec. 11) and residence time (Sec. 12)
# ---------------------------------------------------------------------------------------------


def test_pressure_drop_fits():
    # (5-12) at the 37 m/s slit velocity: 0.67*1369 + 0.84*37 + 25.93 = 974.24 Pa
    assert float(mb.pressure_drop_empty(37.0)) == pytest.approx(974.24, rel=1e-12)
    assert float(mb.pressure_drop_empty(0.0)) == pytest.approx(25.93)
    # (5-9): 0.52 + 135/100 + 6250/100^2 = 2.495
    assert float(mb.xi_apparatus(100.0)) == pytest.approx(2.495, rel=1e-13)
    # (5-7, 5-8): Re* = 0.01 W d_eq / nu = 0.01 * 37 * 0.0158 / 1.47e-5 = 397.7
    assert float(mb.reduced_slit_reynolds(37.0, 0.0158, 1.47e-5)) == pytest.approx(397.69, rel=1e-4)
    # (5-11): (1 + 2.495) * 1.2 * 20^2 / 2
    assert float(mb.pressure_drop_slit_and_apparatus(20.0, 1.2, 100.0)) == pytest.approx(838.8)
    # (3-70): 448 / 100^0.73 + 15 = 448 / 28.840 + 15 = 30.534
    assert float(mb.xi_hobler(100.0)) == pytest.approx(448 / 100**0.73 + 15, rel=1e-14)
    assert float(mb.xi_hobler(100.0)) == pytest.approx(30.534, rel=1e-4)
    with pytest.raises(ValueError):
        mb.xi_apparatus(20.0)
    with pytest.raises(ValueError):
        mb.pressure_drop_empty(50.0)


def test_residence_time():
    W_p = float(mb.discharge_velocity(4e-3, 1.65e-3))
    tau_1 = float(mb.bundle_residence_time(W_p))
    assert tau_1 == pytest.approx(0.21 / W_p)  # = 9.909 s for millet, S = 4 mm
    assert tau_1 == pytest.approx(9.909, rel=1e-3)
    assert float(mb.mean_residence_time(tau_1, 5.0)) == pytest.approx(tau_1 + 5.0)
    assert float(mb.prescribed_residence_time(3, tau_1)) == pytest.approx(3 * tau_1)

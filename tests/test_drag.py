"""Tests of the sphere drag laws (drumheat/models/drag.py)."""

import math

import jax
import numpy as np
import pytest

import drumheat  # noqa: F401
from drumheat.models import drag


def test_schiller_naumann_hand_values():
    # C_D = 24/Re (1 + 0.15 Re^0.687) for Re <= 1000, 0.44 above
    for Re in (0.5, 10.0, 100.0, 999.0):
        expect = 24.0 / Re * (1.0 + 0.15 * Re**0.687)
        assert float(drag.cd_schiller_naumann(Re)) == pytest.approx(expect, rel=1e-14)
    # Re = 100: 0.24 * (1 + 0.15 * 100^0.687) = 0.24 * (1 + 0.15 * 23.659) = 1.0917
    assert float(drag.cd_schiller_naumann(100.0)) == pytest.approx(1.0917, rel=1e-4)
    assert float(drag.cd_schiller_naumann(5000.0)) == 0.44


def test_stokes_limit():
    """C_D -> 24/Re as Re -> 0: the relative correction is 0.15 Re^0.687."""
    for Re in (1e-2, 1e-4, 1e-6):
        ratio = float(drag.cd_schiller_naumann(Re)) / (24.0 / Re)
        assert ratio - 1.0 == pytest.approx(0.15 * Re**0.687, rel=1e-10)
    assert float(drag.cd_schiller_naumann(1e-8) * 1e-8) == pytest.approx(24.0, rel=1e-6)


def test_nearly_continuous_at_newton_switch():
    lo = float(drag.cd_schiller_naumann(1000.0))
    hi = float(drag.cd_schiller_naumann(1000.0001))
    assert abs(lo - hi) / hi < 0.005  # 0.4385 vs 0.44


def test_drag_force_stokes_and_vector():
    d, mu, rho = 1e-5, 1.8e-5, 1.2
    u = 1e-3  # Re = 6.7e-4: Stokes, F = 3 pi mu d u
    F = float(drag.drag_force(u, d, rho, mu))
    assert F == pytest.approx(3 * math.pi * mu * d * u, rel=2e-3)
    F0 = float(drag.drag_force(0.0, d, rho, mu))
    assert F0 == 0.0
    # vector form points along u_rel, magnitude equals the scalar form
    uv = np.array([3.0, 4.0, 0.0])
    Fv = np.asarray(drag.drag_force(uv, 2e-3, rho, mu))
    Fs = float(drag.drag_force(5.0, 2e-3, rho, mu))
    np.testing.assert_allclose(Fv, Fs * uv / 5.0, rtol=1e-13)
    # Newton regime by hand: 1/2 rho C_D pi d^2/4 u^2
    assert Fs == pytest.approx(
        0.5 * rho * float(drag.cd_schiller_naumann(5.0 * 2e-3 * rho / mu)) * math.pi * 4e-6 / 4 * 25,
        rel=1e-13)


def test_terminal_velocity_stokes_and_newton():
    mu, rho_f = 1.8e-5, 1.2
    # Stokes: W = g d^2 (rho_p - rho_f) / (18 mu), checked where Re << 1 (Re ~ 5e-6 here, so
    # the Schiller-Naumann correction 0.15 Re^0.687 is ~3e-5)
    d, rho_p = 1e-6, 2500.0
    W = float(drag.terminal_velocity(d, rho_p, rho_f, mu, drag_law="stokes"))
    assert W == pytest.approx(drag.G * d**2 * (rho_p - rho_f) / (18 * mu), rel=1e-12)
    W_sn = float(drag.terminal_velocity(d, rho_p, rho_f, mu))
    assert W_sn == pytest.approx(W, rel=1e-4)
    # Newton: W = sqrt(4 g d (rho_p - rho_f) / (3 rho_f C_D)) with C_D = 0.44
    d, rho_p = 4.07e-3, 1315.0
    W = float(drag.terminal_velocity(d, rho_p, rho_f, mu))
    assert W * d * rho_f / mu > 1000
    assert W == pytest.approx(math.sqrt(4 * drag.G * d * (rho_p - rho_f) / (3 * rho_f * 0.44)), rel=1e-10)


def test_terminal_velocity_force_balance_intermediate():
    mu, rho_f, d, rho_p = 1.8e-5, 1.2, 0.5e-3, 2500.0
    W = float(drag.terminal_velocity(d, rho_p, rho_f, mu))
    Re = W * d * rho_f / mu
    assert 10 < Re < 1000
    weight = (rho_p - rho_f) * drag.G * math.pi * d**3 / 6
    assert float(drag.drag_force(W, d, rho_f, mu)) == pytest.approx(weight, rel=1e-10)


def test_vectorised_and_differentiable():
    d = np.array([1e-4, 1e-3, 3e-3])
    W = np.asarray(drag.terminal_velocity(d, 2500.0, 1.2, 1.8e-5))
    assert W.shape == (3,) and np.all(np.diff(W) > 0)
    g = jax.grad(lambda u: drag.drag_force(u, 1e-3, 1.2, 1.8e-5))(0.3)
    h = 1e-6
    fd = (float(drag.drag_force(0.3 + h, 1e-3, 1.2, 1.8e-5))
          - float(drag.drag_force(0.3 - h, 1e-3, 1.2, 1.8e-5))) / (2 * h)
    assert float(g) == pytest.approx(fd, rel=1e-6)


def test_unknown_law():
    with pytest.raises(ValueError):
        drag.drag_force(1.0, 1e-3, 1.2, 1.8e-5, drag_law="bogus")

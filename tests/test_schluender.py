"""Schluender contact coefficients against the digest's Table 8-1 values."""

import math

import jax
import pytest

import drumheat as dh
from drumheat.models import schluender


def test_accommodation_coefficient_and_mean_free_path():
    # weigler-thermal-dem.md Table 8-1 / digest note: gamma = 0.8960, l = 2.764e-7 m
    T = 303.15
    gamma_hand = 1.0 / (1.0 + 10 ** (0.6 - (1000.0 / T + 1.0) / 2.8))
    assert schluender.accommodation_coefficient(T) == pytest.approx(gamma_hand, rel=1e-14)
    assert gamma_hand == pytest.approx(0.8960, abs=5e-5)
    R = 8314.0 / 28.96
    l_hand = 2 * (2 - gamma_hand) / gamma_hand * math.sqrt(2 * math.pi * R * T) * 0.0266 / (
        101325.0 * (2 * 1009.0 - R))
    l = schluender.mean_free_path(T, 101325.0, 0.0266, 1009.0, 28.96)
    assert l == pytest.approx(l_hand, rel=1e-13)
    assert l == pytest.approx(2.764e-7, rel=1e-3)


@pytest.mark.parametrize("d,wp,pp", [(0.004, 210.0, 105.0), (0.008, 114.0, 57.0)])
def test_digest_values(d, wp, pp):
    a_wp, a_pp = schluender.contact_coefficients(d)
    # digest note: 209.8 (4 mm) and 114.1 (8 mm); the thesis rounds to 210/105 and 114/57
    assert float(a_wp) == pytest.approx(wp, abs=0.5)
    assert float(a_pp) == pytest.approx(pp, abs=0.25)
    assert float(a_pp) == pytest.approx(float(a_wp) / 2, rel=1e-15)  # eq. [2.10]


def test_decreases_with_size_and_pressure():
    assert schluender.contact_coefficients(0.002)[0] > schluender.contact_coefficients(0.004)[0]
    assert (schluender.contact_coefficients(0.004, p=1e4)[0]
            < schluender.contact_coefficients(0.004)[0])
    g = jax.grad(lambda d: schluender.contact_coefficients(d)[0])(0.004)
    assert g < 0


def test_scene_model_schluender_matches_constant():
    s = dh.load_scene("weigler-glass-wall", {"run.duration": 500.0})
    raw = s.to_dict()
    for eff in ("contact", "wall"):
        raw["heat"][eff] = {"model": "schluender"}
    raw["gas"] = {"temperature": 303.15}
    from drumheat.motion.static import StaticBed
    from drumheat.scene import scene_from_dict

    model, _ = StaticBed(scene_from_dict(raw)).model()
    alphas = {type(e).__name__: float(e.alpha) for e in model.effects}
    assert alphas["ContactConduction"] == pytest.approx(57.06, abs=0.01)
    assert alphas["WallConduction"] == pytest.approx(114.12, abs=0.01)

"""Equalisation criteria (drumheat.results.equalisation) on hand-made histories."""

import numpy as np
import pytest

import drumheat as dh
from drumheat.results.equalisation import equalisation_times, settling_time


def test_settling_time_counts_from_the_last_time_the_criterion_was_met():
    t = np.arange(6.0)
    assert settling_time(t, [False, True, False, True, True, True]) == 3.0
    assert settling_time(t, [True] * 6) == 0.0
    assert settling_time(t, [True, True, True, True, True, False]) is None
    with pytest.raises(ValueError):
        settling_time(t, [True, False])


def test_three_criteria_on_an_exponential_exchange_and_drift():
    # two particles exchanging with rate k while the mean drifts to T_gas with rate a:
    # deviation 10 K exp(-k t) about a mean 300 - 2 exp(-a t); analytic settling times
    k, a, T_gas = 0.1, 0.01, 300.0
    t = np.linspace(0.0, 400.0, 40001)
    mean = T_gas - 2.0 * np.exp(-a * t)
    dev = 10.0 * np.exp(-k * t)
    T = np.stack([mean - dev, mean + dev], axis=1)
    out = equalisation_times(t, T, groups=[0, 1], mass=[1.0, 1.0], T_gas=T_gas, threshold=1.0)
    t_spread = np.log(20.0) / k  # 2 dev = 1 K
    assert out["spread"] == pytest.approx(t_spread, abs=0.02)
    assert out["fraction_means"] == pytest.approx(t_spread, abs=0.02)
    # gas: max |T_i - T_gas| = 2 exp(-a t) + dev <= 1
    gap = 2.0 * np.exp(-a * t) + dev
    assert out["gas"] == pytest.approx(t[np.flatnonzero(gap > 1.0)[-1] + 1])
    assert out["gas"] > out["spread"]


def test_summary_reports_the_criteria_for_a_bed_of_fractions():
    scene = dh.load_scene("weigler-static").replace(**{"run.duration": 60.0,
                                                       "run.output_interval": 30.0})
    res = dh.run(scene)
    eq = res.summary["equalisation"]
    assert set(eq) == {"threshold_K", "spread", "fraction_means", "gas"}
    assert eq["spread"] is None  # 19 K apart at the start; a minute is far too short

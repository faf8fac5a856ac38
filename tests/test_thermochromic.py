"""Tests of the thermochromic measurement chain (drumheat.experiments.thermochromic).

Reference: reference/weigler-thermal-dem.md, section 8 (App. A1 tables, methods 1-3, classes)
and section 12, items 15-17.
"""

import warnings

import matplotlib
import numpy as np
import pandas as pd
import pytest

matplotlib.use("Agg")

from drumheat.experiments import thermochromic as tc  # noqa: E402


@pytest.fixture(scope="module")
def table():
    return tc.calibration_table()


@pytest.fixture(scope="module")
def cals():
    return tc.calibrations()          # PCHIP through Tables A1.1-A1.3


# ------------------------------------------------------------------ shipped data


def test_shipped_tables_are_consistent(table):
    assert list(table.T_C) == [23, 25, 26, 28, 30, 32, 34, 36, 38, 40, 42, 44, 46, 48, 50, 52,
                               54]
    for b in ("heating", "cooling", "combined"):
        assert np.all(np.diff(table[f"intensity_{b}"]) > 0), b
    assert table.control_intensity.between(129.39, 130.33).all()
    # A1.3 = heating branch below 36 degC, cooling branch from 36 degC up (Sec. 3.6.2) ...
    low = table.T_C < 36
    np.testing.assert_array_equal(table.intensity_combined[low], table.intensity_heating[low])
    high = (table.T_C >= 36) & (table.T_C != 38)
    np.testing.assert_array_equal(table.intensity_combined[high],
                                  table.intensity_cooling[high])
    # ... except the printed discrepancy at 38 degC (digest section 12, item 16)
    row = table[table.T_C == 38].iloc[0]
    assert (row.intensity_combined, row.intensity_cooling) == (95.50, 95.00)


# ------------------------------------------------------------------ fits


def test_pchip_reproduces_table_points(cals, table):
    for name, cal in cals.items():
        assert cal.method == "pchip" and cal.monotone
        assert cal.rms_K < 1e-9, name                       # interpolant
        np.testing.assert_allclose(cal(table[f"intensity_{name}"]), table.T_C, atol=1e-9)
        # between the points: leave-one-out error measured 0.49 / 0.42 / 0.71 K
        assert cal.loo_rms_K < 0.8, (name, cal.loo_rms_K)


@pytest.mark.parametrize("branch, rms_max", [("heating", 0.65), ("cooling", 0.45),
                                             ("combined", 0.85)])
def test_poly_degree5_reproduces_table_points(branch, rms_max, table):
    # Measured RMS 0.618 / 0.423 / 0.839 K; degree 5 is the highest degree that is monotone
    # on all three branches.
    cal = tc.calibration(branch, method="poly", degree=5)
    assert cal.monotone
    assert cal.rms_K < rms_max
    assert np.max(np.abs(cal.residuals_K)) < 2.0
    np.testing.assert_allclose(cal(table[f"intensity_{branch}"]), table.T_C, atol=2.0)


def test_high_degree_poly_is_flagged_not_monotone():
    with pytest.warns(UserWarning, match="not monotone"):
        cal = tc.calibration("combined", method="poly", degree=9)
    assert not cal.monotone
    with pytest.raises(ValueError, match="not monotone"):
        cal.inverse(40.0)


def test_combined_curve_monotone_over_its_range(cals):
    cal = cals["combined"]
    grid = np.linspace(*cal.domain, 20001)
    T = cal(grid)
    assert np.all(np.diff(T) > 0)
    assert np.all(cal.derivative(grid) >= 0)
    assert cal.temperature_range_C == (23.0, 54.0)
    # the inverse is exact
    Ts = np.linspace(23.0, 54.0, 63)
    np.testing.assert_allclose(cal(cal.inverse(Ts)), Ts, atol=1e-8)


def test_hysteresis_cooling_reads_colder(cals):
    # same intensity: a cooling particle is colder than a heating one (below the crossing ~51 C)
    I = np.linspace(62.0, 116.0, 200)
    assert np.all(cals["cooling"](I) < cals["heating"](I))


def test_out_of_range_behaviour(cals):
    cal = cals["combined"]
    with pytest.warns(tc.CalibrationRangeWarning, match="2 of 4"):
        T = cal([50.0, 80.0, 130.0, np.nan])
    assert np.isnan(T[0]) and np.isnan(T[2]) and np.isnan(T[3]) and 34 < T[1] < 36
    np.testing.assert_allclose(cal([50.0, 130.0], out_of_range="clip"), [23.0, 54.0])
    with pytest.raises(ValueError, match="outside the calibrated range"):
        cal(130.0, out_of_range="raise")
    with warnings.catch_warnings():
        warnings.simplefilter("error")
        cal([60.0, 118.0])                                 # inside: no warning


def test_fit_calibration_input_errors():
    with pytest.raises(ValueError, match="repeated"):
        tc.fit_calibration([1, 1, 2], [20, 21, 22])
    with pytest.raises(ValueError, match="method"):
        tc.fit_calibration([1, 2, 3], [20, 21, 22], method="spline")
    with pytest.raises(ValueError, match="needs at least"):
        tc.fit_calibration([1, 2, 3], [20, 21, 22], method="poly", degree=3)


def test_printed_polynomials_are_numerically_useless(table):
    """Why drumheat refits (digest section 8 and section 12, item 17)."""
    I = table.intensity_combined.to_numpy()
    T = table.T_C.to_numpy()
    printed = np.asarray(tc.PRINTED_COEFFICIENTS["combined"])
    err = tc.printed_polynomial("combined")(I) - T
    assert np.all(np.abs(err) > 100.0)           # hundreds to ~3e5 K off at every point
    # The list is genuine: a degree-12 polyfit of A1.3 reproduces it (measured ~3e-5 rel.) ...
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")
        refit = np.polyfit(I, T, 12)
    np.testing.assert_allclose(refit, printed, rtol=1e-3)
    assert np.max(np.abs(np.polyval(refit, I) - T)) < 1.0
    # ... and the failure is cancellation: terms of ~2.5e12 sum to ~50, so 6 printed digits
    # cannot carry it.
    terms = np.abs(printed[:, None] * I[None, :] ** np.arange(12, -1, -1)[:, None])
    assert terms.max() > 1e12
    # the degree-9 branch lists fail too, whichever branch they are applied to
    for name in ("heating", "cooling"):
        for b in ("heating", "cooling"):
            e = tc.printed_polynomial(name)(table[f"intensity_{b}"]) - T
            assert np.all(np.abs(e) > 1e3)


# ------------------------------------------------------------------ assignment methods


def _synthetic_run(rng, n=35, n_frames=8, sigma_I=0.3):
    """Cold fraction heats from ~26-30 to ~31-33.5 degC, warm cools from ~44-46 to ~39-40."""
    t = tc.image_times(tc.EVALUATED_IMAGES_RESTING, 30.0)
    tau = 900.0
    decay = np.exp(-(t - t[0]) / tau)[:, None]
    cold0 = rng.uniform(26.0, 30.0, n)
    warm0 = rng.uniform(44.0, 46.0, n)
    T_cold = 33.5 - (33.5 - cold0) * decay
    T_warm = 38.5 + (warm0 - 38.5) * decay
    return t, np.concatenate([T_cold, T_warm], axis=1)


def _noise_tolerance(cal, I_true, sigma_I, mask):
    """4 sigma of a fraction mean from intensity noise, linearised: sigma_T,i = sigma_I |f'|."""
    s = sigma_I * np.abs(cal.derivative(I_true))
    s = np.where(mask, s, 0.0)
    n = mask.sum(axis=1)
    return 4.0 * np.sqrt((s ** 2).sum(axis=1)) / n


@pytest.mark.parametrize("curves", ["combined", "branches"])
def test_method3_recovers_fraction_means(cals, curves):
    rng = np.random.default_rng(7)
    sigma_I = 0.3
    t, T_true = _synthetic_run(rng, sigma_I=sigma_I)
    truth = np.arange(70) < 35
    if curves == "combined":
        I_true = cals["combined"].inverse(T_true)
        slope_cold = slope_warm = cals["combined"]
    else:
        I_true = np.where(truth, cals["heating"].inverse(T_true), cals["cooling"].inverse(T_true))
        slope_cold, slope_warm = cals["heating"], cals["cooling"]
    assert np.all(np.isfinite(I_true))
    I_meas = I_true + rng.normal(0.0, sigma_I, I_true.shape)
    perm = rng.permutation(70)                   # particle order must not matter
    asg = tc.assign_temperatures(I_meas[:, perm], method=3, n_heating=35, curves=curves,
                                 cals=cals)
    # fractions are > 20 intensity units apart, noise 0.3: no particle may be swapped
    np.testing.assert_array_equal(asg.heating, np.broadcast_to(truth[perm], asg.heating.shape))
    means = tc.fraction_means(asg.T_C, asg.heating, t)
    cold = np.broadcast_to(truth, T_true.shape)
    tol_cold = _noise_tolerance(slope_cold, I_true, sigma_I, cold)
    tol_warm = _noise_tolerance(slope_warm, I_true, sigma_I, ~cold)
    err_cold = means["T_mean_C:cold"].to_numpy() - T_true[:, :35].mean(axis=1)
    err_warm = means["T_mean_C:warm"].to_numpy() - T_true[:, 35:].mean(axis=1)
    assert np.all(np.abs(err_cold) < tol_cold), (err_cold, tol_cold)
    assert np.all(np.abs(err_warm) < tol_warm), (err_warm, tol_warm)
    # the tolerance is meaningful (it grows to ~0.4 K late in the run, where the cold fraction
    # sits at 31-34 degC: there the curve is flat, 71.7 -> 73.0 for 2 K, about 1.5 K per unit)
    assert np.all(tol_cold < 0.5) and np.all(tol_warm < 0.5)
    np.testing.assert_allclose(means["T_mean"], means["T_mean_C"] + 273.15)
    assert (means["n:cold"] == 35).all() and (means["n:warm"] == 35).all()


def test_method2_and_method3_differ_when_the_split_drifts(cals):
    # 35 cold spheres near I=70; the warm fraction: 30 bright at ~110 and 5 that have cooled
    # to ~75 (e.g. beside the wall). Mean intensity = 87.5, so method 2 calls those 5 cold.
    rng = np.random.default_rng(3)
    I = np.concatenate([70.0 + rng.uniform(-1, 1, 35), 110.0 + rng.uniform(-1, 1, 30),
                        75.0 + rng.uniform(-1, 1, 5)])[None, :]
    truth = np.arange(70) < 35
    a2 = tc.assign_temperatures(I, method=2, cals=cals)
    a3 = tc.assign_temperatures(I, method=3, n_heating=35, cals=cals)
    a1 = tc.assign_temperatures(I, method=1, fraction=truth, cals=cals)
    assert a2.heating.sum() == 40 and a3.heating.sum() == 35
    np.testing.assert_array_equal(a3.heating[0], truth)
    np.testing.assert_array_equal(a1.heating[0], truth)
    m2 = tc.fraction_means(a2.T_C, a2.heating)
    m3 = tc.fraction_means(a3.T_C, a3.heating)
    # same particle temperatures (combined curve), different fraction means
    np.testing.assert_array_equal(a2.T_C, a3.T_C)
    assert m2["T_mean_C:cold"][0] > m3["T_mean_C:cold"][0] + 0.1
    assert m2["T_mean_C:warm"][0] > m3["T_mean_C:warm"][0] + 1.0
    assert m2["T_mean_C"][0] == m3["T_mean_C"][0]
    # with two branches the misassigned 5 are also read on the wrong curve
    b2 = tc.assign_temperatures(I, method=2, curves="branches", cals=cals)
    b3 = tc.assign_temperatures(I, method=3, curves="branches", cals=cals)
    assert set(np.unique(b3.branch)) == {"heating", "cooling"}
    wrong = b2.heating[0] & ~truth
    assert wrong.sum() == 5
    assert np.all(b2.T_C[0, wrong] > b3.T_C[0, wrong] + 3.0)   # hysteresis: ~5 K off


def test_method_argument_errors(cals):
    I = np.full((1, 5), 80.0)
    with pytest.raises(ValueError, match="odd"):
        tc.assign_temperatures(I, method=3, cals=cals)
    with pytest.raises(ValueError, match="method 1"):
        tc.assign_temperatures(I, method=1, cals=cals)
    with pytest.raises(ValueError, match="method=4"):
        tc.assign_temperatures(I, method=4, cals=cals)


# ------------------------------------------------------------------ distributions


def test_distributions_sum_to_one_and_end_at_one():
    rng = np.random.default_rng(11)
    T = rng.uniform(24.0, 51.0, (4, 70))
    T[0, :3] = np.nan
    d = tc.temperature_distribution(T)
    assert d.counts.shape == (4, 25)             # 25 classes of 1 K, not 50 (section 12.15)
    np.testing.assert_allclose((d.q0 * d.widths_K).sum(axis=1), 1.0)
    np.testing.assert_allclose(d.Q0[:, -1], 1.0)
    assert np.all(np.diff(d.Q0, axis=1) >= 0)
    assert d.n_valid.tolist() == [67, 70, 70, 70]
    # with "clip", Q0 at an interior upper edge is the true fraction below it
    fin = np.isfinite(T[1])
    for k, edge in enumerate(d.edges_C[1:-1]):
        assert d.Q0[1, k] == pytest.approx(np.mean(T[1, fin] < edge))
    e = tc.temperature_distribution(T, outside="exclude")
    np.testing.assert_array_equal(e.n_valid, d.n_valid - d.n_below - d.n_above)
    np.testing.assert_allclose(e.Q0[:, -1], 1.0)


# ------------------------------------------------------------------ CSV and evaluate


def test_csv_round_trip_and_evaluate(tmp_path, cals):
    rng = np.random.default_rng(5)
    t, T_true = _synthetic_run(rng, n=4, n_frames=8)
    I = cals["combined"].inverse(T_true) + rng.normal(0.0, 0.1, T_true.shape)
    I[2, 5] = np.nan                              # particle 5 not measured in frame 3
    particles = np.array([11, 12, 13, 14, 21, 22, 23, 24])
    fraction = np.array(["cold"] * 4 + ["warm"] * 4)
    path = tmp_path / "run.csv"
    tc.write_intensity_csv(path, I, t, frames=np.array(tc.EVALUATED_IMAGES_RESTING),
                           particles=particles, fraction=fraction)
    assert path.read_text().splitlines()[0] == "frame,time_s,particle,intensity,fraction"
    data = tc.read_intensity_csv(path)
    np.testing.assert_array_equal(data.frames, tc.EVALUATED_IMAGES_RESTING)
    np.testing.assert_array_equal(data.time_s, t)
    np.testing.assert_array_equal(data.particles, particles)
    np.testing.assert_array_equal(data.intensity, I)         # NaN in the same place
    np.testing.assert_array_equal(data.fraction, np.arange(8) < 4)

    ev = tc.evaluate(path, method=3)              # n_heating from the fraction column
    assert isinstance(ev.means, pd.DataFrame) and len(ev.means) == 8
    assert (ev.means["n_misassigned"] == 0).all()
    np.testing.assert_array_equal(ev.means["t"], t)
    np.testing.assert_array_equal(ev.means["frame"], tc.EVALUATED_IMAGES_RESTING)
    assert ev.means["n:warm"].tolist()[2] == 3 and ev.means["n_invalid"].tolist()[2] == 1
    assert (ev.means["T_mean_C:cold"] < 34).all() and (ev.means["T_mean_C:warm"] > 38).all()
    g = ev.distributions.groupby("frame")
    np.testing.assert_allclose(g.apply(lambda x: (x.q0 * (x.T_hi_C - x.T_lo_C)).sum(),
                                       include_groups=False), 1.0)
    np.testing.assert_allclose(g.Q0.last(), 1.0)
    ev1 = tc.evaluate(path, method=1)
    np.testing.assert_allclose(ev1.means["T_mean_C:cold"], ev.means["T_mean_C:cold"])


def test_csv_reader_errors(tmp_path):
    p = tmp_path / "bad.csv"
    p.write_text("frame,time_s,particle\n1,60,1\n")
    with pytest.raises(ValueError, match="missing column"):
        tc.read_intensity_csv(p)
    p.write_text("frame,time_s,particle,intensity\n1,60,1,70\n1,60,1,71\n")
    with pytest.raises(ValueError, match="twice"):
        tc.read_intensity_csv(p)
    p.write_text("frame,time_s,particle,intensity\n1,60,1,70\n1,65,2,71\n")
    with pytest.raises(ValueError, match="different time_s"):
        tc.read_intensity_csv(p)
    p.write_text("frame,time_s,particle,intensity,fraction\n1,60,1,70,cold\n2,90,1,71,warm\n")
    with pytest.raises(ValueError, match="both fractions"):
        tc.read_intensity_csv(p)


def test_image_times_match_tables_3_5_and_3_6():
    minutes = np.array([1, 2, 4, 6, 11, 16, 21, 31])
    np.testing.assert_array_equal(tc.image_times(tc.EVALUATED_IMAGES_RESTING, 30.0),
                                  60.0 * minutes)
    np.testing.assert_array_equal(tc.image_times(tc.EVALUATED_IMAGES_MIXED, 5.0),
                                  60.0 * minutes)


def test_plot_calibration(cals):
    import matplotlib.pyplot as plt

    fig = tc.plot_calibration(cals)
    ax = fig.axes[0]
    assert len(ax.lines) == 6                      # 3 curves + 3 point sets
    assert len(ax.get_legend().get_texts()) == 3
    plt.close(fig)

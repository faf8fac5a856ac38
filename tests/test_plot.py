"""Figures: every plot function returns a Figure with the expected axes, labels and artists."""

import matplotlib

matplotlib.use("Agg")

import matplotlib.pyplot as plt  # noqa: E402
import numpy as np  # noqa: E402
import pandas as pd  # noqa: E402
import pytest  # noqa: E402
from matplotlib.collections import EllipseCollection, LineCollection  # noqa: E402
from matplotlib.figure import Figure  # noqa: E402
from matplotlib.patches import Circle  # noqa: E402

import drumheat as dh  # noqa: E402
from drumheat.results import plot  # noqa: E402


@pytest.fixture(scope="module")
def static():
    return dh.run("weigler-static", overrides={"run.duration": 120.0}, progress=False)


@pytest.fixture(scope="module")
def heated():
    return dh.run("weigler-glass-wall", overrides={"run.duration": 500.0, "groups.0.count": 120},
                  progress=False)


@pytest.fixture(autouse=True)
def _close():
    yield
    plt.close("all")


def _labels(ax):
    return [t.get_text() for t in ax.get_legend().get_texts()] if ax.get_legend() else []


def test_mean_temperatures_with_measured_points(static):
    ts = static.timeseries
    data = pd.DataFrame({"t": ts["t"], "T_mean:cold": ts["T_mean:cold"] + 0.3,
                         "T_mean:warm": ts["T_mean:warm"] - 0.3})
    fig = plot.plot_mean_temperatures(static, data=data)
    assert isinstance(fig, Figure)
    ax = fig.axes[0]
    assert ax.get_xlabel() == "time / min" and "°C" in ax.get_ylabel()
    assert {"all particles", "cold", "warm", "measured"} <= set(_labels(ax))
    # 3 simulated lines + 2 measured series + the legend proxy
    markers = [ln for ln in ax.lines if ln.get_marker() == "o" and len(ln.get_xdata())]
    assert len(markers) == 2
    np.testing.assert_allclose(markers[0].get_ydata(), data["T_mean:cold"] - plot.C0)
    assert any(a.get_ylabel() == "K" for a in ax.child_axes)  # kelvin axis


def test_mean_temperatures_into_given_ax_and_csv(static, tmp_path):
    csv = tmp_path / "m.csv"
    pd.DataFrame({"t": [0.0, 60.0], "T_mean": [310.0, 311.0]}).to_csv(csv, index=False)
    fig0, ax = plt.subplots()
    fig = plot.plot_mean_temperatures(static, ax=ax, data=csv)
    assert fig is fig0
    assert "measured" in _labels(ax)


def test_distributions_at_chosen_times(static):
    fig = plot.plot_distributions(static, times=[0.0, 60.0, 120.0])
    a0, a1 = fig.axes[:2]
    assert "q0" in a0.get_ylabel() and "1 K" in a0.get_ylabel()
    assert a1.get_ylabel().startswith("Q0")
    assert _labels(a0) == ["t = 0 min", "t = 1 min", "t = 2 min"]
    # q0 integrates to 1 over 1 K classes; Q0 ends at 1
    for patch in a0.patches:
        values = patch.get_data().values
        assert values.sum() == pytest.approx(1.0)
    for line in a1.lines:
        assert line.get_ydata()[-1] == pytest.approx(1.0)
    fig2 = plot.plot_distributions(static, times_index=[0, -1])
    assert len(fig2.axes[0].patches) == 2
    fig3, axes = plt.subplots(2, 1)
    assert plot.plot_distributions(static, times_index=[0], ax=axes) is fig3


def test_alpha_overall_log_axes(heated, static):
    fig = plot.plot_alpha_overall(heated)
    a0, a1 = fig.axes[:2]
    assert a0.get_xscale() == "log" and a0.get_yscale() == "log"
    assert a1.get_xscale() == "log"
    assert "W/(m² K)" in a0.get_ylabel() and a1.get_ylabel() == "d ln alpha / d ln t"
    assert any("-0.5" in s for s in _labels(a1))
    with pytest.raises(ValueError, match="alpha_overall"):
        plot.plot_alpha_overall(static)
    fig2, axes = plt.subplots(1, 2)
    assert plot.plot_alpha_overall(heated, ax=axes) is fig2


def test_snapshot_to_scale_with_walls_and_colorbar(static):
    fig = plot.plot_snapshot(static, -1)
    ax = fig.axes[0]
    (coll,) = [c for c in ax.collections if isinstance(c, EllipseCollection)]
    assert len(coll.get_offsets()) == 70
    np.testing.assert_allclose(coll._widths, 0.5 * 0.004)  # half-widths in data units (m)
    shells = [p for p in ax.patches if isinstance(p, Circle)]
    assert len(shells) == 1 and shells[0].get_radius() == pytest.approx(0.025)
    np.testing.assert_allclose(coll.get_array(), static.trajectory.T[-1] - plot.C0)
    cbar_ax = fig.axes[1]
    assert cbar_ax.get_ylabel() == "temperature / °C"
    assert any(a.get_ylabel() == "K" for a in cbar_ax.child_axes)
    assert ax.get_xlabel() == "x / mm"


def test_draw_walls_plates_and_cylinders():
    fig, ax = plt.subplots()
    artists = plot.draw_walls(ax, [
        {"kind": "cylinder", "radius": 0.1},
        {"kind": "circle", "center": (0.02, 0.0), "radius": 0.005},
        {"kind": "plate", "start": (0.03, 0.0), "end": (0.1, 0.0)},
    ])
    assert len(artists) == 3
    assert [type(a).__name__ for a in artists] == ["Circle", "Circle", "Line2D"]
    np.testing.assert_allclose(artists[2].get_xdata(), [0.03, 0.1])
    with pytest.raises(ValueError, match="kind"):
        plot.draw_walls(ax, [{"kind": "cone"}])


def test_draw_walls_from_geometry_objects():
    from drumheat.geometry import walls as gw

    fig, ax = plt.subplots()
    artists = plot.draw_walls(ax, [gw.DrumShell(radius=0.1),
                                   gw.RadialPlate(r_inner=0.02, r_outer=0.1, phase=np.pi / 2)])
    assert artists[0].get_radius() == pytest.approx(0.1)
    np.testing.assert_allclose(artists[1].get_ydata(), [0.02, 0.1])
    np.testing.assert_allclose(artists[1].get_xdata(), [0.0, 0.0], atol=1e-12)


def test_contact_network(static):
    from drumheat.thermal.network import find_contacts_2d_drum

    fig = plot.plot_contact_network(static, index=1)
    ax = fig.axes[0]
    (lines,) = [c for c in ax.collections if isinstance(c, LineCollection)]
    pairs, _ = find_contacts_2d_drum(static.trajectory.position[1], static.trajectory.diameter,
                                     0.05, static.scene.heat.contact.gap_tolerance)
    assert len(lines.get_segments()) == len(pairs) > 50
    T = static.trajectory.T[1]
    i, j = pairs.T
    expected = 105.0 * np.pi * 0.004**2 / 4 * np.abs(T[i] - T[j])
    np.testing.assert_allclose(lines.get_array(), expected)
    labels = [a.get_xlabel() + a.get_ylabel() for a in fig.axes]
    assert any("heat flow" in s and "W" in s for s in labels)
    # a given pair array, coloured by temperature difference
    fig2 = plot.plot_contact_network(static, index=1, pairs=[[0, 1], [2, 3]], color_by="dT")
    (lines2,) = [c for c in fig2.axes[0].collections if isinstance(c, LineCollection)]
    np.testing.assert_allclose(lines2.get_array(), [abs(T[0] - T[1]), abs(T[2] - T[3])])
    with pytest.raises(ValueError, match="color_by"):
        plot.plot_contact_network(static, color_by="colour")


def test_snapshot_and_network_from_a_result_folder(static, tmp_path):
    folder = static.save(tmp_path / "res", figures=False)
    fr = plot.read_particles(folder)
    assert fr.T.shape == static.trajectory.T.shape and fr.drum_diameter == 0.05
    assert fr.group_names == ["cold", "warm"]
    fig = plot.plot_snapshot(folder, 0)
    assert isinstance(fig, Figure)
    fig, axes = plt.subplots(1, 2)
    plot.plot_snapshot(fr, 0, ax=axes[0], colorbar=False)
    plot.plot_contact_network(fr, 0, ax=axes[1])
    assert len(axes[1].collections) == 2


def test_save_figures_writes_pngs(static, tmp_path):
    files = plot.save_figures(static, tmp_path)
    assert {f.name for f in files} == {"mean_temperatures.png", "temperature_distributions.png",
                                       "snapshot_final.png"}
    assert all(f.stat().st_size > 1000 for f in files)

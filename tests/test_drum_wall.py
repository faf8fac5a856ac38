"""A drum wall with its own heat capacity ([heat.drum_wall], docs/models/drum-wall.md)."""

import math

import jax.numpy as jnp
import numpy as np
import pytest

import drumheat as dh
from drumheat import assemble
from drumheat.materials import material
from drumheat.models.drum_wall import two_capacity_solution
from drumheat.motion import make_motion
from drumheat.scene import SceneError, load_scene
from drumheat.thermal.solvers import initial_state

pytestmark = pytest.mark.filterwarnings("ignore::drumheat.mechanics.DEMAccuracyWarning")

GAS_WALL = {"thickness": 0.001, "outside": "gas", "outer_temperature": 400.0,
            "outer_alpha": 20.0, "segments": 1, "inner_alpha": 5.0}


def lumped_scene(**over):
    """The weigler-static packing, all particles at one temperature, no contact conduction and
    no loss: the particles touching the wall all follow one ODE (a lumped bed), the others
    stay as they are. One segment, a drum at rest: the two-capacity system exactly."""
    s = load_scene("weigler-static")
    s = s.without("heat.contact", "heat.loss")
    s = s.replace({"groups.1.temperature": 299.15, "drum.wall_temperature": 300.0,
                   "heat.wall": {"model": "constant", "alpha": 300.0},
                   "heat.drum_wall": dict(GAS_WALL), "run.duration": 600.0,
                   "run.output_interval": 20.0, "run.rtol": 1e-10, "run.atol": 1e-9})
    return s.replace(over) if over else s


def test_thin_wall_and_lumped_bed_match_the_two_capacity_solution():
    scene = lumped_scene()
    res = dh.run(scene, progress=False)
    traj = res.trajectory
    touching = np.abs(traj.T[-1] - traj.T[0]) > 1e-9
    n_w = int(traj.n_wall_contacts[0])
    assert touching.sum() == n_w > 5
    # every touching particle follows the same curve: the bed is lumped
    assert np.ptp(traj.T[:, touching], axis=1).max() < 1e-10
    d, R = 0.004, 0.025
    A = 2 * math.pi * R * d  # 2D: the monolayer is one particle diameter deep
    steel = material("steel")
    s, h_o, h_i = GAS_WALL["thickness"], GAS_WALL["outer_alpha"], GAS_WALL["inner_alpha"]
    U = A / (1 / h_o + s / steel.conductivity)
    G = n_w * 300.0 * math.pi / 4 * d**2
    H = h_i * (A - min(A, n_w * d**2))
    C_w = s * steel.density * steel.heat_capacity * A
    C_b = float(traj.capacity[touching].sum())
    Tw, Tb = two_capacity_solution(traj.t, C_w, C_b, U, G, T_o=400.0, H=H, T_g=310.65,
                                   T_w0=300.0, T_b0=299.15)
    dev_w = np.max(np.abs(traj.drum_wall["T"][:, 0] - Tw))
    dev_b = np.max(np.abs(traj.T[:, touching][:, 0] - Tb))
    assert dev_w < 1e-6 and dev_b < 1e-6, (dev_w, dev_b)
    assert Tb[-1] - Tb[0] > 20.0  # the bed heated a lot: the comparison means something
    assert res.summary["energy_balance_rel_error"] < 1e-12


def test_fixed_outer_temperature_conducts_through_the_wall():
    scene = lumped_scene(**{"heat.drum_wall": {"thickness": 0.002, "outside": "temperature",
                                               "outer_temperature": 350.0, "segments": 1,
                                               "material": "steel", "conductivity": 0.5}})
    traj = dh.run(scene, progress=False).trajectory
    touching = np.abs(traj.T[-1] - traj.T[0]) > 1e-9
    n_w = touching.sum()
    A = 2 * math.pi * 0.025 * 0.004
    steel = material("steel")
    C_w = 0.002 * steel.density * steel.heat_capacity * A
    Tw, Tb = two_capacity_solution(traj.t, C_w, float(traj.capacity[touching].sum()),
                                   0.5 / 0.002 * A, n_w * 300.0 * math.pi / 4 * 0.004**2,
                                   T_o=350.0, T_w0=300.0, T_b0=299.15)
    np.testing.assert_allclose(traj.drum_wall["T"][:, 0], Tw, rtol=0, atol=1e-6)
    np.testing.assert_allclose(traj.T[:, touching][:, 0], Tb, rtol=0, atol=1e-6)


def test_two_capacity_solution_solves_its_ode():
    args = dict(C_w=2.0, C_b=1.0, U=0.3, G=0.1, T_o=400.0, P=1.5, H=0.05, T_g=300.0,
                T_w0=310.0, T_b0=290.0)
    t = np.linspace(0, 50, 11)
    eps = 1e-4
    Tw, Tb = two_capacity_solution(t, **args)
    Tw1, Tb1 = two_capacity_solution(t + eps, **args)
    Tw0, Tb0 = two_capacity_solution(t - eps, **args)
    dTw, dTb = (Tw1 - Tw0) / (2 * eps), (Tb1 - Tb0) / (2 * eps)
    rhs_w = (1.5 + 0.3 * (400 - Tw) - 0.1 * (Tw - Tb) - 0.05 * (Tw - 300)) / 2.0
    rhs_b = 0.1 * (Tw - Tb) / 1.0
    np.testing.assert_allclose(dTw, rhs_w, atol=1e-7)
    np.testing.assert_allclose(dTb, rhs_b, atol=1e-7)
    assert Tw[0] == pytest.approx(310.0) and Tb[0] == pytest.approx(290.0)
    with pytest.raises(ValueError):
        two_capacity_solution(t, 1.0, 1.0, 0.0, 0.1, T_w0=1.0, T_b0=1.0)


def _balance_parts(res):
    traj = res.trajectory
    w = traj.drum_wall
    stored_w = (w["T"] - w["T"][0]) @ w["capacity"]
    stored_b = (traj.T - traj.T[0]) @ traj.capacity
    return traj, w, stored_w, stored_b


def test_energy_balance_of_a_remixed_bed_with_turning_segments():
    """Random re-mixing in a turning drum, heat by a prescribed flux, losses of wall and
    particles to the gas: outside = wall + bed + gas to round-off."""
    s = load_scene("weigler-glass-random")
    s = s.replace({"run.duration": 200.0, "drum.rpm": 3.0, "gas": {"temperature": 293.0},
                   "heat.loss": {"alphaA": 1e-4},
                   "heat.drum_wall": {"thickness": 0.003, "outside": "flux",
                                      "outer_flux": 2000.0, "segments": 24,
                                      "inner_alpha": 8.0}})
    res = dh.run(s, progress=False)
    traj, w, stored_w, stored_b = _balance_parts(res)
    into = w["Q_outside"] - w["Q_gas"] + traj.Q["gas"]
    scale = np.max(np.abs(w["Q_outside"]))
    assert np.max(np.abs(stored_w + stored_b - into)) / scale < 1e-10
    # the wall alone: stored = outside - bed - gas
    assert np.max(np.abs(stored_w - (w["Q_outside"] - traj.Q["wall"] - w["Q_gas"]))) / scale \
        < 1e-10
    assert res.summary["energy_balance_rel_error"] < 1e-10
    # the flux is all that comes in from outside: q A t
    np.testing.assert_allclose(w["Q_outside"], 2000.0 * w["area"].sum() * traj.t, rtol=1e-12)
    # the segments under the bed are colder than the free ones and they differ
    assert np.ptp(w["T"][-1]) > 1.0
    ts = res.timeseries
    for col in ("T_wall_mean", "T_wall_min", "T_wall_max", "Q_outside", "Q_wall_gas",
                "Q_wall_stored"):
        assert col in ts
    assert "alpha_overall" not in ts


def test_coupled_dem_carries_the_wall_and_closes_the_balance(tmp_path):
    from tests.test_coupled import dem_scene

    scene = dem_scene(**{"drum.wall_temperature": 330.0,
                         "heat.wall": {"model": "constant", "alpha": 200.0},
                         "heat.drum_wall": {"thickness": 0.001, "outside": "temperature",
                                            "outer_temperature": 360.0, "segments": 8,
                                            "inner_alpha": 10.0}})
    res = dh.run(scene, out=tmp_path / "dem", progress=False)
    traj, w, stored_w, stored_b = _balance_parts(res)
    assert w["T"].shape == (len(traj.t), 8)
    assert traj.Q["wall"][-1] > 0 and w["Q_outside"][-1] > 0 and w["Q_gas"][-1] > 0
    into = w["Q_outside"] - w["Q_gas"] + traj.Q["gas"]
    assert np.max(np.abs(stored_w + stored_b - into)) / np.max(np.abs(w["Q_outside"])) < 1e-10
    assert res.summary["energy_balance_rel_error"] < 1e-10
    with np.load(tmp_path / "dem" / "wall.npz") as f:
        np.testing.assert_array_equal(f["T_wall"], w["T"])
        assert f["angle_edges"].shape == (9,)
    assert (tmp_path / "dem" / "drum_wall.png").exists()


def test_segments_turn_with_the_drum():
    model, _ = assemble.thermal_model(lumped_scene(**{"heat.drum_wall.segments": 4,
                                                      "drum.rpm": 15.0}))
    dw = model.drum_wall
    angle = jnp.array([0.1, math.pi / 2 + 0.1, math.pi + 0.1, -0.1])
    np.testing.assert_array_equal(dw.segment(angle, 0.0), [0, 1, 2, 3])
    # 15 rpm: a quarter turn in 1 s; the segment that was at angle 0.1 is now at pi/2 + 0.1
    np.testing.assert_array_equal(dw.segment(angle, 1.0), [3, 0, 1, 2])
    assert float(dw.area) == pytest.approx(2 * math.pi * 0.025 * 0.004 / 4)


def test_absent_table_builds_and_carries_nothing():
    scene = load_scene("weigler-glass-random")
    model, T0 = assemble.thermal_model(scene)
    assert model.drum_wall is None
    assert set(initial_state(model, T0)) == {"T", "Q"}
    bed = make_motion(scene)
    assert bed.net.wall_angle is None
    assert "wall_angle" not in bed.initial_state()["contacts"]


@pytest.mark.parametrize("over, key", [
    ({"heat.drum_wall.outer_temperature": None}, "heat.drum_wall.outer_temperature"),
    ({"heat.drum_wall.outer_flux": 100.0}, "heat.drum_wall.outer_flux"),
    ({"heat.drum_wall.thickness": -0.001}, "heat.drum_wall.thickness"),
    ({"heat.drum_wall.segments": 0}, "heat.drum_wall.segments"),
    ({"heat.drum_wall.outside": "steam"}, "heat.drum_wall.outside"),
    ({"heat.drum_wall.material": "unobtainium"}, "heat.drum_wall.material"),
    ({"heat.drum_wall.inner_alpha": -1.0}, "heat.drum_wall.inner_alpha"),
    ({"drum.wall_temperature": None}, "drum.wall_temperature"),
    ({"heat.wall": None}, "heat.wall"),
    ({"gas": None, "heat.drum_wall.inner_alpha": 5.0}, "gas.temperature"),
    ({"drum.sections": 4}, "drum.sections"),
    ({"heat.internal": {"shells": 4}}, "heat.internal"),
])
def test_bad_input_names_the_key(over, key):
    with pytest.raises(SceneError) as err:
        lumped_scene(**over)
    assert key in str(err.value)


@pytest.mark.parametrize("model", ["fluidized", "replay"])
def test_motion_models_without_the_wall_refuse_it(model):
    with pytest.raises(SceneError, match="motion.model.*static, random, dem"):
        lumped_scene(**{"motion.model": model})


def test_explicit_solver_converges_to_the_closed_form_and_refuses_a_large_step():
    errs = []
    for dt in (0.2, 0.1):
        scene = lumped_scene(**{"run.solver": "explicit", "run.dt": dt, "run.duration": 200.0})
        traj = dh.run(scene, progress=False).trajectory
        touching = np.abs(traj.T[-1] - traj.T[0]) > 1e-9
        n_w = touching.sum()
        A = 2 * math.pi * 0.025 * 0.004
        steel = material("steel")
        U = A / (1 / 20.0 + 0.001 / steel.conductivity)
        Tw, Tb = two_capacity_solution(
            traj.t, 0.001 * steel.density * steel.heat_capacity * A,
            float(traj.capacity[touching].sum()), U, n_w * 300.0 * math.pi / 4 * 0.004**2,
            T_o=400.0, H=5.0 * (A - n_w * 0.004**2), T_g=310.65, T_w0=300.0, T_b0=299.15)
        errs.append(max(np.max(np.abs(traj.drum_wall["T"][:, 0] - Tw)),
                        np.max(np.abs(traj.T[:, touching][:, 0] - Tb))))
    assert errs[1] < 0.05
    assert errs[0] / errs[1] == pytest.approx(2.0, rel=0.05)  # forward Euler: first order
    with pytest.raises(SceneError, match="run.dt"):
        make_motion(lumped_scene(**{"run.solver": "explicit", "run.dt": 40.0}))


def test_explicit_solver_with_turning_segments_closes_the_balance():
    s = load_scene("weigler-glass-random")
    s = s.replace({"run.duration": 100.0, "run.solver": "explicit", "drum.rpm": 3.0,
                   "heat.drum_wall": {"thickness": 0.003, "outside": "temperature",
                                      "outer_temperature": 400.0, "segments": 12}})
    res = dh.run(s, progress=False)
    assert res.summary["energy_balance_rel_error"] < 1e-12
    assert np.ptp(res.trajectory.drum_wall["T"][-1]) > 0.01  # the segments differ


def test_ensemble_over_wall_parameters_equals_individual_runs():
    base = lumped_scene(**{"run.duration": 100.0})
    variants = [{"heat.drum_wall.thickness": 0.001}, {"heat.drum_wall.thickness": 0.004,
                                                      "heat.drum_wall.outer_alpha": 50.0}]
    ens = dh.run_ensemble(base, variants, progress=False)
    assert ens.vmapped
    for k, v in enumerate(variants):
        one = dh.run(base.replace(v), progress=False)
        np.testing.assert_allclose(ens[k].trajectory.drum_wall["T"], one.trajectory.drum_wall["T"],
                                   rtol=0, atol=1e-9)
        np.testing.assert_allclose(ens[k].T, one.T, rtol=0, atol=1e-9)
    assert ens[0].summary["T_wall_mean"] != ens[1].summary["T_wall_mean"]


def test_dem_refuses_a_wall_too_thin_for_its_thermal_step():
    from tests.test_coupled import dem_scene

    scene = dem_scene(**{"drum.wall_temperature": 330.0, "dem.thermal_substeps": 50,
                         "heat.wall": {"model": "constant", "alpha": 200.0},
                         "heat.drum_wall": {"thickness": 1e-7, "outside": "temperature",
                                            "outer_temperature": 360.0, "segments": 360}})
    with pytest.raises(SceneError, match="heat.drum_wall.thickness"):
        make_motion(scene)

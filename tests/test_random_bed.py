"""Semi-discrete penetration model (motion model "random", weigler-thermal-dem.md 6.1, 6.5)."""

import jax
import jax.numpy as jnp
import numpy as np
import pytest

import drumheat as dh
from drumheat.motion.random import RandomBed
from drumheat.motion import make_motion
from drumheat.runner import trace
from drumheat.scene import load_scene, scene_from_dict


def mini(**motion):
    """70 glass spheres d = 8 mm in a 100 mm drum heated through the wall (a small A8 bed)."""
    raw = dict(name="mini-random", dim=2,
               run=dict(duration=400.0, output_interval=10.0, seed=3),
               drum=dict(diameter=0.1, wall_temperature=343.0),
               groups=[dict(name="glass", count=70, diameter=0.008, material="glass",
                            temperature=293.0)],
               heat=dict(contact=dict(alpha=57.0), wall=dict(alpha=114.0)),
               motion=dict(model="random", **{"t_R": 20.0, **motion}))
    return scene_from_dict(raw)


def test_builtin_scene_is_the_thesis_set_up():
    s = load_scene("weigler-glass-random")
    assert (s.n_particles, s.groups[0].diameter, s.drum.diameter) == (370, 0.008, 0.25)
    assert (s.heat.contact.alpha, s.heat.wall.alpha, s.motion.t_R) == (57.0, 114.0, 40.0)
    assert (s.drum.wall_temperature, s.groups[0].temperature) == (343.0, 293.0)
    assert s.motion.model == "random" and s.motion.remix == "permute"
    assert isinstance(make_motion(s), RandomBed)


@pytest.mark.parametrize("remix", ["permute", "mean"])
def test_energy_balance_to_round_off(remix):
    res = dh.run(mini(remix=remix), progress=False)
    assert res.summary["energy_balance_rel_error"] < 1e-12
    assert "alpha_overall" in res.timeseries
    # heat flows in from the wall: the bed warms and stays below the wall temperature
    T = res.timeseries["T_mean"].to_numpy()
    assert np.all(np.diff(T) > 0) and T[-1] < 343.0


def test_remix_conserves_the_mean():
    bed = make_motion(mini())
    model, _ = bed.model()
    C = np.asarray(model.particles.capacity)
    rng = np.random.default_rng(0)
    T = 293.0 + 50.0 * rng.random(len(C))
    # permute: positions exchange particles; the heat content of the positions is unchanged
    perm = bed.permutation(1)
    assert sorted(perm) == list(range(len(C)))
    assert np.sum(C[perm] * T[perm]) == pytest.approx(np.sum(C * T), rel=1e-15)
    # mean: every particle at the capacity-weighted mean
    Tm = np.asarray(RandomBed.mix_to_mean(jnp.asarray(T), jnp.asarray(C)))
    assert np.ptp(Tm) == 0
    assert np.sum(C * Tm) == pytest.approx(np.sum(C * T), rel=1e-15)
    # over a whole run with outputs just before and after each re-mix the mean is continuous
    scene = mini(remix="mean").with_overrides({"run.duration": 60.0})
    eps = 1e-6
    bed = make_motion(scene).with_options(times=np.array(
        [0.0, 20.0 - eps, 20.0, 20.0 + eps, 40.0 - eps, 40.0, 40.0 + eps, 60.0]))
    T, Q = trace(bed)
    Tcap = np.asarray(T) @ C / C.sum()
    assert abs(Tcap[3] - Tcap[1]) < 1e-5 and abs(Tcap[6] - Tcap[4]) < 1e-5  # ~ q eps / C
    assert np.ptp(np.asarray(T)[3]) < 1e-3 < np.ptp(np.asarray(T)[2])  # reset after 20 s


def test_mean_and_permute_differ():
    a = dh.run(mini(remix="permute"), progress=False).timeseries
    b = dh.run(mini(remix="mean"), progress=False).timeseries
    k = a["t"].to_numpy() == 30.0
    assert abs(a["T_mean"][k].item() - b["T_mean"][k].item()) > 1e-3
    assert (a["T_max"] - a["T_min"])[k].item() > 2 * (b["T_max"] - b["T_min"])[k].item()


def test_permutations_are_reproducible_and_seeded():
    s = mini()
    T1 = dh.run(s, progress=False).T
    T2 = dh.run(s, progress=False).T
    assert np.array_equal(T1, T2)
    T3 = dh.run(s.with_overrides({"run.seed": 4}), progress=False).T
    assert not np.allclose(T1, T3)


def test_very_long_rest_time_equals_the_static_bed():
    s = mini(t_R=1.0e6)
    T_random = dh.run(s, progress=False).T
    T_static = dh.run(s.with_overrides({"motion.model": "static"}), progress=False).T
    assert np.max(np.abs(T_random - T_static)) < 1e-12


@pytest.mark.parametrize("remix", ["mean", "permute"])
def test_short_rest_time_approaches_the_well_mixed_limit(remix):
    """t_R -> 0: all particles at one temperature, the mean a lumped exponential with the wall
    conductance G = alpha_wp sum_wall pi d^2 / 4 (eq. [1.10] with a constant coefficient)."""
    errors = {}
    for t_R in (8.0, 2.0):
        s = mini(remix=remix, t_R=t_R).with_overrides({"run.duration": 200.0})
        res = dh.run(s, progress=False)
        bed = make_motion(s)
        model, _ = bed.model()
        C = float(np.sum(model.particles.capacity))
        d = bed.packing.diameter[bed.wall_particles]
        G = 114.0 * np.sum(np.pi * d**2 / 4)
        t = res.timeseries["t"].to_numpy()
        T_lumped = 343.0 - 50.0 * np.exp(-G * t / C)
        errors[t_R] = np.max(np.abs(res.timeseries["T_mean"].to_numpy() - T_lumped))
        spread = (res.timeseries["T_max"] - res.timeseries["T_min"]).to_numpy()[-1]
        if t_R == 2.0:
            assert errors[t_R] < 0.05 * (343.0 - 293.0)
            assert spread < 0.2 * (343.0 - res.timeseries["T_mean"].to_numpy()[-1])
    static = dh.run(mini(t_R=1e6).with_overrides({"run.duration": 200.0}), progress=False)
    err_static = np.max(np.abs(static.timeseries["T_mean"].to_numpy() - T_lumped))
    assert errors[2.0] < 0.5 * errors[8.0] < err_static


def test_unequal_particles_swap_only_within_their_size_and_conserve_energy():
    raw = mini().to_dict()
    raw["groups"] = [dict(name="glass", count=30, diameter=0.008, material="glass",
                          temperature=293.0),
                     dict(name="alu", count=20, diameter=0.008, material="aluminium",
                          temperature=320.0),
                     dict(name="small", count=20, diameter=0.005, material="glass",
                          temperature=300.0)]
    s = scene_from_dict(raw)
    bed = make_motion(s)
    for k in (1, 2, 3):
        p = bed.permutation(k)
        assert np.array_equal(bed.slot_diameter[p], bed.slot_diameter)
    res = dh.run(s, progress=False)
    assert res.summary["energy_balance_rel_error"] < 1e-12
    traj = res.trajectory
    # particles move with their temperature: the positions of the 5 mm particles stay 5 mm
    # positions, and the particles of a group change position
    small = traj.group == 2
    assert not np.array_equal(traj.position[0], traj.position[-1])
    d_at = {tuple(np.round(p, 9)): d for p, d in zip(bed.packing.position, bed.slot_diameter)}
    assert all(d_at[tuple(np.round(p, 9))] == 0.005 for p in traj.position[-1][small])


def test_gradient_matches_central_differences():
    s = mini().with_overrides({"run.duration": 100.0, "run.rtol": 1e-12, "run.atol": 1e-10})
    bed = make_motion(s).with_options(autodiff="forward")
    w = np.arange(70) % 7 + 1.0  # a weighted particle average, sensitive to both parameters

    def f(p):
        T, _ = trace(bed, {"heat.wall.alpha": p[0], "heat.contact.alpha": p[1]})
        return T[-1] @ w / w.sum()

    p0 = jnp.array([114.0, 57.0])
    g = np.asarray(jax.jacfwd(f)(p0))
    for i in range(2):
        h = 1e-4 * float(p0[i])  # truncation ~ h^2 f''' (1e-10 rel), round-off ~ 1e-13 K / h
        e = jnp.zeros(2).at[i].set(h)
        fd = float((f(p0 + e) - f(p0 - e)) / (2 * h))
        assert g[i] == pytest.approx(fd, rel=1e-6)

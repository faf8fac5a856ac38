"""Coupled thermal DEM (motion 'dem') and replay of recorded contacts (motion 'replay')."""

import jax
import jax.numpy as jnp
import numpy as np
import pytest

import drumheat as dh
from drumheat.mechanics.deposition import Packing
from drumheat.motion import make_motion
from drumheat.scene import load_scene, scene_from_dict
from drumheat.scene.rules import dem_critical_time_step

pytestmark = pytest.mark.filterwarnings("ignore::drumheat.mechanics.DEMAccuracyWarning")


def dem_scene(tmp_path=None, **over):
    """30 aluminium spheres (soft contacts) in the 50 mm drum, two fractions, 12 rpm."""
    raw = load_scene("weigler-static").to_dict()
    raw["name"] = "coupled-test"
    raw["groups"][0]["count"] = raw["groups"][1]["count"] = 15
    raw["run"].update(duration=0.2, output_interval=0.05, solver="explicit")
    raw["drum"]["rpm"] = 12.0
    raw["motion"] = {"model": "dem"}
    # the step counts below assume dt = 0.2 t_crit, above the dashpot limit (this is about heat
    # and replay, not about the forces of sticking contacts; the module ignores the warning)
    raw["dem"] = {"stiffness": 2.0e4, "thermal_substeps": 1}
    raw["dem"]["dt"] = 0.2 * dem_critical_time_step(scene_from_dict(raw))
    scene = scene_from_dict(raw)
    return scene.with_overrides(over) if over else scene


def test_closed_moving_bed_conserves_heat_to_round_off():
    scene = dem_scene(**{"heat.loss.alphaA": 0.0})
    res = dh.run(scene, progress=False)
    traj = res.trajectory
    stored = traj.T @ traj.capacity
    assert np.max(np.abs(stored - stored[0])) / stored[0] < 1e-14
    # the particles moved and exchanged heat meanwhile
    assert np.max(np.linalg.norm(traj.position[-1] - traj.position[0], axis=1)) > 1e-3
    assert res.timeseries["T_mean:cold"].iloc[-1] > 299.15 + 1e-3
    assert res.summary["energy_balance_rel_error"] < 1e-12


def test_replay_reproduces_the_recorded_run_to_round_off(tmp_path):
    # record every thermal step of 11 mechanical steps (the output interval holds 1859 = 11 x
    # 169 steps)
    scene = dem_scene(**{"dem.thermal_substeps": 11})
    bed = make_motion(scene)
    assert bed.steps_per_output == 1859
    scene = scene.with_overrides({"dem.record_interval": scene.run.output_interval / 169,
                                  "dem.dt": bed.dt})
    assert make_motion(scene).dt == pytest.approx(bed.dt, rel=1e-12)
    res = dh.run(scene, out=tmp_path / "dem", progress=False)
    raw = scene.to_dict()
    raw["motion"] = {"model": "replay"}
    raw["replay"] = {"file": str(tmp_path / "dem" / "contacts.npz"), "cyclic": False}
    del raw["dem"]
    replay = dh.run(scene_from_dict(raw), progress=False)
    np.testing.assert_allclose(replay.T, res.T, rtol=0, atol=1e-11)
    np.testing.assert_allclose(replay.timeseries["Q_loss"], res.timeseries["Q_loss"], rtol=1e-10)


@pytest.mark.parametrize("gap", [0.0, 0.01])
def test_resting_dem_bed_matches_the_static_model(gap):
    # The coupled update sees the same contacts and heat flows as the static model on the same
    # positions (contacts where the surfaces overlap or the gap is within the conduction gap
    # tolerance, 0 or the default 1 % of d), to round-off.
    # (A whole-run comparison is not a good test here: a monolayer resting in a drum keeps
    # creeping for seconds - its contact count drifts from 34 to 37 - so the static snapshot
    # and the DEM bed genuinely differ after a while.)
    import jax.numpy as jnp

    from drumheat.motion.coupling import initial_extra, thermal_network
    from drumheat.thermal.network import ContactNetwork, find_contacts_2d_drum

    scene = dem_scene(**{"drum.rpm": 0.0, "heat.contact.gap_tolerance": gap})
    bed = make_motion(scene)
    model, T0 = bed.model()
    T = T0 + jnp.linspace(0.0, 3.0, 30)  # every contact carries heat
    dem = bed.make_dem(model)
    state = dem.init(bed.packing_positions())
    state = state._replace(extra=initial_extra(model, T, state.nbrs.idx.shape[1], 30, 1,
                                                bed.dt))
    state = dem.run(state, 2000)
    c = dem.contacts(state)
    h = bed.dt
    net_dem = thermal_network(state.nbrs.idx, 30, c.pair_conducts.astype(jnp.int32),
                              c.wall_conducts * h, jnp.asarray(bed.wall_heated), 1, h, h)
    pairs, wall = find_contacts_2d_drum(np.asarray(state.position), bed.diameter, 0.05, gap,
                                        wall_tolerance=bed.setup.conduction_gap[1])
    assert len(pairs) == int(np.sum(c.pair_conducts)) > 20
    assert len(wall) == int(np.sum(c.wall_conducts))
    if gap == 0:
        assert np.array_equal(c.pair_conducts, c.pair_mask)
    T = state.extra.T
    q_dem, _ = model.heat_flows(T, net_dem)
    q_static, _ = model.heat_flows(T, ContactNetwork.from_arrays(pairs, wall))
    np.testing.assert_allclose(q_dem, q_static, rtol=1e-12, atol=1e-15)
    # and a coupled step applies exactly that flow on the contacts at its end positions (to the
    # round-off of T ~ 300 K)
    new, c_new = dem.step(state)
    net_new = thermal_network(new.nbrs.idx, 30, c_new.pair_conducts.astype(jnp.int32),
                              c_new.wall_conducts * h, jnp.asarray(bed.wall_heated), 1, h, h)
    q_new, _ = model.heat_flows(T, net_new)
    np.testing.assert_allclose(new.extra.T, T + h * q_new / model.particles.capacity,
                               rtol=0, atol=1e-12)


@pytest.mark.bitwise
def test_a_run_that_records_nothing_carries_no_recording_accumulators():
    # without dem.record_interval the coupled state leaves the recording's per-pair and
    # per-wall-slot accumulators out (one int32 per slot less to carry, remap and fold);
    # the temperatures, accounts and contact count are those of a state that carries them,
    # bit for bit, through rebuilds and thermal sub-steps
    from drumheat.motion.coupling import contact_count, initial_extra, recorded_times

    scene = dem_scene(**{"dem.thermal_substeps": 3})
    bed = make_motion(scene)
    assert bed.initial_state().extra.pair.rec_time is None
    model, T0 = bed.model()
    T = T0 + jnp.linspace(0.0, 3.0, 30)
    dem = bed.dem
    start = dem.init(bed.packing_positions())
    cap = start.nbrs.idx.shape[1]
    runs = [dem.run(start._replace(extra=initial_extra(model, T, cap, 30, len(bed.walls),
                                                       bed.dt, record=record)), 3001)
            for record in (True, False)]
    assert runs[0].n_rebuilds > 0 and runs[1].extra.rec_wall_time is None
    np.testing.assert_array_equal(runs[0].extra.T, runs[1].extra.T)
    assert {a: float(q) for a, q in runs[0].extra.Q.items()} == \
        {a: float(q) for a, q in runs[1].extra.Q.items()}
    heated = bed.wall_heated
    assert contact_count(runs[0].extra, heated) == contact_count(runs[1].extra, heated)
    assert float(jnp.sum(recorded_times(runs[0].extra)[0])) > 0
    with pytest.raises(ValueError, match="records no contact times"):
        recorded_times(runs[1].extra)


def test_contact_times_are_whole_steps():
    # the coupled heat counts each pair's and wall slot's conducting steps in int32: after k
    # steps from a fresh state the recorded times are dt times the number of steps each
    # contact conducted (pair_conducts / wall_conducts of every step, counted here), exactly,
    # through the thermal sub-steps' folds; the output interval's count is their sum
    from drumheat.motion.coupling import contact_count, mean_contacts, recorded_times

    bed = make_motion(dem_scene(**{"dem.thermal_substeps": 3, "dem.record_interval": 0.05}))
    dem = bed.dem
    state = bed.initial_state()
    assert state.extra.pair.time.dtype == jnp.int32 == state.extra.wall_time.dtype
    pairs, walls = 0, 0
    for _ in range(8):  # two thermal steps and two steps after
        state, c = dem.step(state)
        pairs = pairs + np.asarray(c.pair_conducts, np.int64)
        walls = walls + np.asarray(c.wall_conducts, np.int64)
    assert int(state.n_rebuilds) == 0  # the slots stayed the same pairs
    assert pairs.max() == 8 and walls.max() == 8  # lasting contacts among them
    pt, wt = recorded_times(state.extra)
    assert pt.dtype == jnp.float64
    np.testing.assert_array_equal(np.asarray(pt), pairs * bed.dt)
    np.testing.assert_array_equal(np.asarray(wt), walls * bed.dt)
    count = contact_count(state.extra, bed.wall_heated)
    heated = np.tile(np.asarray(bed.wall_heated, bool), bed.n)
    assert float(count.pair) == pairs.sum() * bed.dt
    assert float(count.wall) == walls[heated].sum() * bed.dt
    # with the bound of the thermal sub-steps the pending pair times sum in int32: the same
    # count (every partial sum a whole number of steps), also the output rows' mean
    assert contact_count(state.extra, bed.wall_heated, bed.substeps) == count
    assert (mean_contacts(state.extra, bed.wall_heated, 0.1, bed.substeps)
            == mean_contacts(state.extra, bed.wall_heated, 0.1))


def test_step_sums_in_int32_are_exact():
    # the contact-time sums of the thermal step and of a rebuild's remap run in int32 where
    # that is exact, so that XLA writes no float64 copy of the per-slot counts (it set the
    # memory peak of a rebuilding step, docs/performance.md): the same numbers as the float64
    # sums; beyond the int32 bound the float64 sum; and the remap's count of the dropped pairs
    # is exact even where each of its two int32 sums wraps around
    from drumheat.motion.coupling import CoupledHeat, ContactCount, PairTimes, _steps

    counts = jnp.asarray(np.random.default_rng(1).integers(0, 11, 100_000), jnp.int32)
    exact = float(np.sum(np.asarray(counts, np.int64)))
    assert float(_steps(counts, 10)) == exact == float(_steps(counts))
    big = jnp.full(3, 2**30, jnp.int32)  # 3 * 2^30 > 2^31: summed in float64
    assert float(_steps(big, 2**30)) == 3 * 2.0**30
    old = PairTimes(jnp.asarray([2**30, 2**30, 2**30, 5], jnp.int32), None)
    keep = jnp.asarray([0, 1, 2, -1])  # the last pair dropped, a new one in its slot

    def remap(a):
        return jnp.where(keep >= 0, a[jnp.maximum(keep, 0)], 0)

    zero = jnp.zeros(())
    new, count, _ = CoupledHeat.remap_pair_arrays(
        (old, ContactCount(zero, zero), jnp.asarray(3, jnp.int32)), remap)
    np.testing.assert_array_equal(np.asarray(new.time), [2**30, 2**30, 2**30, 0])
    assert float(count.pair) == 5.0  # 3 * 2^30 + 5 - 3 * 2^30, both sums past int32


def test_padding_slots_of_the_thermal_network_add_nothing():
    # the DEM's contact network keeps the neighbour list's padding index n (dropped by the
    # effects' scatters, clamped by their gathers) rather than pointing the padding at a real
    # particle, whose atomic adds a GPU serialises (docs/performance.md, GPU): the heat flows
    # are those of the network without the padding slots, bit for bit
    from drumheat.motion.coupling import thermal_network
    from drumheat.thermal.contact import ContactConduction
    from drumheat.thermal.particles import ThermalParticles

    n, h = 5, 1e-3
    idx = jnp.array([[0, 0, 1, 3, n, n, n], [1, 2, 4, 4, n, n, n]])
    steps = jnp.array([4, 2, 1, 4, 4, 4, 4], jnp.int32)  # padding steps are not read
    no_wall = (jnp.zeros(n), jnp.array([False]), 1, h, h / 4)
    net = thermal_network(idx, n, steps, *no_wall)
    cut = thermal_network(idx[:, :4], n, steps[:4], *no_wall)
    assert np.all(np.asarray(net.pair_i)[4:] == n)
    assert np.array_equal(net.pair_weights(n), [1.0, 0.5, 0.25, 1.0, 0.0, 0.0, 0.0])
    particles = ThermalParticles(diameter=jnp.full(n, 4e-3), mass=jnp.full(n, 1e-4),
                                 heat_capacity=jnp.full(n, 900.0))
    T = jnp.array([300.0, 310.0, 320.0, 330.0, 340.0])
    effect = ContactConduction(alpha=jnp.asarray(100.0))
    q = effect.heat_flow(T, particles, net)
    assert np.all(np.asarray(q) != 0)
    np.testing.assert_array_equal(q, effect.heat_flow(T, particles, cut))
    np.testing.assert_array_equal(effect.conductance_sum(particles, net),
                                  effect.conductance_sum(particles, cut))


@pytest.mark.skipif(jax.default_backend() != "cpu",
                    reason="compares runs that differ only in the sub-cycling, so the flow must "
                           "repeat bit for bit: on a GPU two runs of this scene differ by ~1e-2 K "
                           "(docs/long-runs.md)")
def test_subcycling_error_shrinks_with_the_interval():
    # the output interval holds 11151 = 27 x 413 mechanical steps; sub-cycling factors that
    # divide it keep the outputs on thermal-step boundaries
    base = dem_scene(**{"run.duration": 0.6, "run.output_interval": 0.3})
    bed = make_motion(base)
    ref = dh.run(base, progress=False).T[-1]
    errs = []
    for k in (27, 9, 3):
        assert bed.steps_per_output % k == 0
        T = dh.run(base.with_overrides({"dem.thermal_substeps": k}), progress=False).T[-1]
        errs.append(np.max(np.abs(T - ref)))
    assert errs[0] > errs[1] > errs[2] > 0
    assert errs[0] < 1e-3  # K, out of a 19 K spread


def test_cyclic_replay_and_interfraction_contacts(tmp_path):
    scene = dem_scene(**{"dem.record_interval": 0.01})
    res = dh.run(scene, out=tmp_path / "dem", progress=False)
    counts = res.timeseries["interfraction_contacts"].to_numpy()
    assert counts.shape == (5,) and np.all(counts >= 0)
    raw = scene.to_dict()
    raw["motion"] = {"model": "replay"}
    raw["replay"] = {"file": str(tmp_path / "dem" / "contacts.npz")}
    raw["run"]["duration"] = 1.0  # five cycles of the 0.2 s recording
    del raw["dem"]
    rep = dh.run(scene_from_dict(raw), progress=False)
    assert rep.summary["energy_balance_rel_error"] < 1e-12
    ts = rep.timeseries
    assert np.all(np.diff(ts["T_mean:cold"]) > 0) and np.all(np.diff(ts["T_mean:warm"]) < 0)


@pytest.mark.bitwise
def test_replay_after_continues_the_coupled_run_cyclically():
    scene = dem_scene(**{"run.duration": 0.6, "run.output_interval": 0.1,
                         "dem.record_interval": 0.01, "dem.replay_after": 0.2})
    res = dh.run(scene, progress=False)
    full = dh.run(scene.with_overrides({"dem.replay_after": 0.6}), progress=False)
    # identical while coupled, then close: the replay repeats the first 0.2 s of contacts
    np.testing.assert_array_equal(res.T[:3], full.T[:3])
    dev = np.max(np.abs(res.timeseries["T_mean:cold"] - full.timeseries["T_mean:cold"]))
    gain = full.timeseries["T_mean:cold"].iloc[-1] - full.timeseries["T_mean:cold"].iloc[0]
    assert 0 < dev < 0.5 * gain
    assert res.summary["energy_balance_rel_error"] < 1e-12
    assert np.isnan(res.timeseries["interfraction_contacts"].iloc[-1])


def _random_recorder(rng, n, k, directory=None):
    """A ContactRecorder of ``k`` random intervals (``directory``: its files there)."""
    from drumheat.motion.dem import ContactRecorder

    rec = ContactRecorder(n, 1, 0.01, wall_heated=np.ones(1, bool), wall_ids=np.zeros(1, int),
                          diameter=np.full(n, 0.01), group=np.zeros(n, int), scene_toml="",
                          directory=directory)
    rec.add_positions(rng.normal(size=(n, 3)))
    c = rec.columns
    for _ in range(k):
        m, w = rng.integers(0, 6), rng.integers(0, 3)
        c["pair_i"].append(rng.integers(0, n, m))
        c["pair_j"].append(rng.integers(0, n, m))
        c["pair_duration"].append(rng.uniform(0, 0.01, m))
        rec.pair_ptr.append(rec.pair_ptr[-1] + m)
        c["wall_particle"].append(rng.integers(0, n, w))
        c["wall_index"].append(np.zeros(w, np.int32))
        c["wall_duration"].append(rng.uniform(0, 0.01, w))
        rec.wall_ptr.append(rec.wall_ptr[-1] + w)
        rec.add_positions(rng.normal(size=(n, 3)))
    return rec


def test_recording_from_an_interval_on_is_what_the_replay_keeps_of_it(tmp_path):
    """ContactRecorder.arrays(first) (what the switch to the replay takes) equals the whole
    recording cut the way Recording(rec, first) cuts it, for a recorder filled interval by
    interval and for one restored from a checkpoint (one array per quantity), in memory and
    with its intervals in files."""
    from drumheat.motion.dem import ContactRecorder
    from drumheat.motion.replay import Recording

    n, k = 6, 5
    for directory in (None, tmp_path / "log"):
        rec = _random_recorder(np.random.default_rng(0), n, k, directory)
        restored = ContactRecorder.from_arrays(rec.checkpoint_arrays(), directory)
        for first in range(k):
            whole = Recording(rec.arrays(), first=first)
            for r in (rec, restored):
                cut = Recording(r.arrays(first=first))
                for a, b in zip(jax.tree_util.tree_leaves((whole.net.pairs, whole.net.walls)),
                                jax.tree_util.tree_leaves((cut.net.pairs, cut.net.walls))):
                    np.testing.assert_array_equal(a, b)
                np.testing.assert_array_equal(whole.positions, cut.positions)
                np.testing.assert_array_equal(whole.match, cut.match)


def test_replay_in_blocks_is_the_replay_of_the_whole_cycle(monkeypatch):
    """Recording.networks(g, n) holds the rows of the whole cycle's networks at the cyclic
    intervals g, g + 1, ... (across the cycle's end too), and Recording.replay, which puts a
    block of intervals at a time on the device (the whole cycle where it fits), gives the
    temperatures and accounts of the whole cycle's replay bit for bit, restarts included,
    whatever the block (on a GPU to round-off: its scatter-adds add in no fixed order)."""
    import functools

    from drumheat.motion import replay
    from drumheat.motion.replay import Recording

    n, k = 30, 5
    recording = Recording(_random_recorder(np.random.default_rng(2), n, k).arrays())
    whole = recording.net
    for g, m in ((0, 5), (3, 4), (9, 7)):
        block = recording.networks(g, m)
        assert int(block.g0) == g
        for a, b in zip(jax.tree_util.tree_leaves((whole.pairs, whole.walls)),
                        jax.tree_util.tree_leaves((block.pairs, block.walls))):
            np.testing.assert_array_equal(a[(g + np.arange(m)) % k], b)
    model, T0 = make_motion(dem_scene()).model()
    T0 = jnp.asarray(T0, float) + jnp.linspace(0.0, 40.0, n)  # unequal, so every contact flows
    Q0 = {a: jnp.zeros(()) for a in model.accounts}
    g = jnp.asarray(3, jnp.int64)
    ref = whole.advance(model, T0, Q0, g, 12)  # two restarts, at g = 5 and g = 10
    same = (np.testing.assert_array_equal if jax.default_backend() == "cpu"
            else functools.partial(np.testing.assert_allclose, rtol=1e-12))
    row = recording.pair_width * 16 + recording.wall_width * 16
    for per_block in (1, 2, 5, 12):
        monkeypatch.setattr(replay, "REPLAY_BLOCK_BYTES", per_block * row)
        assert recording.block_intervals() == per_block  # 5 and 12: the whole cycle fits
        got = recording.replay(model, T0, Q0, g, 12)
        for a, b in zip(jax.tree_util.tree_leaves(ref), jax.tree_util.tree_leaves(got)):
            same(b, a)
    assert not np.array_equal(ref[0], T0)


def test_recording_in_files_is_the_recording_in_memory(tmp_path):
    """A recorder with a directory gives the arrays of one in memory (the same dtypes), reads
    them memory-mapped, holds no interval in memory, and its checkpoint arrays hold only the
    pointers; a recorder adopting the files after a stop cuts off what was written past the
    checkpoint and goes on from there."""
    from drumheat.motion.dem import ContactRecorder

    n, k = 7, 6
    mem = _random_recorder(np.random.default_rng(1), n, k)
    disk = _random_recorder(np.random.default_rng(1), n, k, tmp_path / "log")
    a, b = mem.arrays(), disk.arrays()
    assert a.keys() == b.keys()
    for key in a:
        np.testing.assert_array_equal(a[key], b[key])
        assert np.asarray(a[key]).dtype == np.asarray(b[key]).dtype
    assert isinstance(b["pair_i"], np.memmap) and isinstance(b["positions"], np.memmap)
    assert not any(col._blocks for col in disk.columns.values())
    ck = disk.checkpoint_arrays()
    assert ck["spooled"] and not ({"pair_i", "positions"} & set(ck))
    assert {"pair_i", "positions"} <= set(mem.checkpoint_arrays())
    # a stop after the checkpoint: two more intervals written, then the run resumes
    for _ in range(2):
        disk.columns["pair_i"].append(np.arange(3))
        disk.add_positions(np.zeros((n, 3)))
    again = ContactRecorder.from_arrays(ck, tmp_path / "log")
    for key, v in again.arrays().items():
        np.testing.assert_array_equal(v, a[key])
    again.add_positions(np.ones((n, 3)))
    np.testing.assert_array_equal(again.arrays()["positions"][:-1], a["positions"])
    np.testing.assert_array_equal(again.arrays()["positions"][-1], 1.0)
    with pytest.raises(ValueError, match="directory"):
        ContactRecorder.from_arrays(ck)


def test_builtin_dem_scenes_load_and_build():
    for name in ("weigler-mixed", "weigler-glass-drum-9.55", "weigler-glass-drum-47.75",
                 "weigler-glass-mixing-9.55", "weigler-glass-mixing-47.75"):
        bed = make_motion(load_scene(name))
        assert bed.dt <= 0.2 * bed.t_crit * (1 + 1e-9)
        assert bed.steps_per_output * bed.dt == pytest.approx(bed.scene.run.output_interval)


def test_summary_says_what_set_the_time_step():
    """weigler-mixed (damping 0.3): the dashpot limit, 0.079 t_crit, is below 0.1 t_crit; a
    smaller safety factor or a given dt set the step themselves."""
    for over, origin, ratio in (({}, "tangential dashpots", 0.0786),
                                ({"dem.safety_factor": 0.05}, "safety_factor", 0.05),
                                ({"dem.dt": 5e-6}, "dem.dt", None)):
        motion = make_motion(load_scene("weigler-mixed", over))
        info = motion.backend_info()["time_step"]
        assert origin in info["set_by"]
        assert info["dt_s"] == motion.dt and info["t_crit_s"] == motion.t_crit
        if ratio is not None:  # fitted to the recording interval: at most the limit
            assert ratio * 0.999 < info["dt_over_t_crit"] <= ratio * 1.0001

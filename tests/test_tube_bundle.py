"""Scene ``kraychev-tube-bundle`` and motion model ``moving_bed`` (drumheat/motion/moving_bed.py).

Geometry of the staggered bundle and the slit, the recycling boundary (inlet temperature, no
particle lost, discharge counter = recycled particles), per-tube heat accounts and the energy
balance of a short coupled run, and a slit narrower than a particle that lets nothing through.
"""

import jax
import jax.numpy as jnp
import numpy as np
import pytest

from drumheat.geometry.walls import FixedCylinder, Plane, Segment
from drumheat.motion.moving_bed import MovingBed, hopper_walls, measure, particles_to_fill
from drumheat.results.result import build_timeseries, energy_balance
from drumheat.runner import simulate
from drumheat.scene import SceneError, load_scene

# a small, fast variant: one pitch deep in rows, 2 pitches wide, ~60 particles of 4 mm
SMALL = {"hopper.rows": 1, "hopper.columns": 2, "hopper.settle_time": 0.0,
         "hopper.bottom_height": 0.01, "hopper.bundle_clearance": 0.006,
         "hopper.insertion_height": 0.015, "hopper.measure_from": 0.0,
         "groups.0.diameter": 0.004, "hopper.depth": 0.0104, "run.output_interval": 0.05}


def test_scene_builds_staggered_bundle_and_slit():
    s = load_scene("kraychev-tube-bundle")
    h = s.hopper
    assert (h.tube_diameter, h.pitch, h.row_pitch) == (0.014, 0.025, 0.025)
    g = hopper_walls(h)
    walls = g.walls
    assert isinstance(walls[0], Plane) and isinstance(walls[1], Plane)
    assert isinstance(walls[2], Segment) and isinstance(walls[3], Segment)
    tubes = [walls[k] for k in g.tube_index]
    assert all(isinstance(t, FixedCylinder) and t.radius == pytest.approx(0.007) for t in tubes)
    assert all(t.temperature == h.tube_temperature for t in tubes)
    assert {t.wall_id for t in tubes} == set(g.tube_index.tolist())  # one id per tube
    c = g.tube_center
    rows = np.unique(np.round(c[:, 1], 9))
    assert len(rows) == h.rows
    np.testing.assert_allclose(np.diff(rows), 0.025)  # s2
    for k, y in enumerate(rows):
        xs = np.sort(c[np.isclose(c[:, 1], y), 0])
        np.testing.assert_allclose(np.diff(xs), 0.025)  # s1 within a row
        # staggered: the lowest row has no tube on the axis (x = +-s1/2), the next one has
        assert np.any(np.isclose(xs, 0.0)) == (k % 2 == 1)
    # side walls through tube centres of every other row: those are half tubes
    xw = g.half_width
    assert xw == pytest.approx(0.5 * h.columns * h.pitch)
    half = np.isclose(np.abs(c[:, 0]), xw)
    np.testing.assert_array_equal(g.tube_fraction, np.where(half, 0.5, 1.0))
    # slit: the bottom plates end at x = +-S/2, y = 0; a point in the slit is free of walls
    assert walls[2].b == pytest.approx((-0.5 * h.slit_width, 0.0))
    assert walls[3].b == pytest.approx((0.5 * h.slit_width, 0.0))
    x = jnp.array([[0.0, 0.0, 0.005]])
    for w in walls[2:4]:
        assert float(w.distance(x)[0]) == pytest.approx(0.5 * h.slit_width)


def test_scene_checks():
    with pytest.raises(SceneError, match="dim"):
        load_scene("kraychev-tube-bundle", {"dim": 2})
    with pytest.raises(SceneError, match="hopper.depth"):
        load_scene("kraychev-tube-bundle", {"hopper.depth": 0.005})
    with pytest.raises(SceneError, match="hopper.slit_width"):
        load_scene("kraychev-tube-bundle", {"hopper.slit_width": 0.06})


def _small(S, duration, T_tube=291.15):
    s = load_scene("kraychev-tube-bundle", dict(SMALL, **{"hopper.slit_width": S,
                                                           "run.duration": duration,
                                                           "hopper.tube_temperature": T_tube}))
    n = particles_to_fill(s.hopper, 0.004, 0.004)
    return s.with_overrides({"groups.0.count": n})


def test_recycling_hook_resets_particle():
    """A particle below the slit re-enters on a free insertion site, at rest, at t_1."""
    s = _small(0.016, 0.05)
    bed = MovingBed(s)
    model, T0 = bed.model()
    dem = bed.make_dem(model)
    pos = bed.packing_positions().copy()
    pos[0] = [0.0, bed.y_exit - 0.002, 0.005]
    state = dem.init(pos)
    from drumheat.motion.coupling import initial_extra

    extra = initial_extra(model, T0, state.nbrs.idx.shape[1], bed.n, bed.n_walls,
                          bed.dt, per_wall=True, accounts=("inflow",))
    extra = extra.replace(T=extra.T.at[0].set(280.0), flow=bed.initial_flow())
    state = state._replace(extra=extra, velocity=state.velocity.at[0].set([0.1, -0.5, 0.0]),
                           wall_spring=state.wall_spring.at[0].set(1e-4))
    new = jax.jit(bed.make_boundary())(state)
    p = np.asarray(new.position[0])
    assert np.min(np.linalg.norm(bed.sites - p, axis=1)) < 1e-12  # on an insertion site
    assert float(new.extra.T[0]) == s.hopper.inlet_temperature
    np.testing.assert_array_equal(np.asarray(new.velocity[0]), 0.0)
    np.testing.assert_array_equal(np.asarray(new.wall_spring[0]), 0.0)
    f = new.extra.flow
    assert int(f["n_out"]) == 1 and int(f["passes"][0]) == 1
    assert float(f["m_out"]) == pytest.approx(float(bed.mech.mass[0]))
    cap = float(model.particles.capacity[0])
    assert float(new.extra.Q["inflow"]) == pytest.approx(cap * (s.hopper.inlet_temperature
                                                                    - 280.0))
    # the others are untouched
    np.testing.assert_array_equal(np.asarray(new.position[1:]), np.asarray(state.position[1:]))


def test_short_run_recycles_and_balances_energy():
    s = _small(0.016, 0.3)
    bed = MovingBed(s)
    traj = simulate(bed, progress=False)
    r = traj.records
    n_out = int(r["n_out"][-1])
    assert n_out > 0, "nothing flowed through a 16 mm slit"
    # the discharge counter is the number of recycled particles, the mass their mass
    assert int(r["passes"].sum()) == n_out
    assert r["m_out"][-1] == pytest.approx(float(np.sum(r["passes"] * np.asarray(bed.mech.mass))))
    # no particle lost: all inside the hopper (or waiting just below the slit)
    pos = traj.position[-1]
    assert np.all(np.isfinite(pos))
    assert np.all(np.abs(pos[:, 0]) <= bed.geometry.half_width + 1e-9)
    assert np.all(pos[:, 1] > bed.y_exit - 0.05)
    # temperatures stay between inlet and tubes; recycled ones carried cool solids in
    h = s.hopper
    assert traj.T.min() >= h.inlet_temperature - 1e-9
    assert traj.T.max() <= h.tube_temperature + 1e-9
    assert traj.Q["wall"][-1] > 0 and traj.Q["inflow"][-1] < 0
    assert traj.n_wall_contacts[-1] > 0 and traj.n_contacts[-1] > 0  # tube and bed contacts
    # per-tube heat accounts add up to the wall account
    ts = build_timeseries(s, traj)
    tube_cols = [c for c in ts.columns if c.startswith("Q_tube:")]
    assert len(tube_cols) == len(bed.geometry.tube_index)
    np.testing.assert_allclose(ts[tube_cols].sum(axis=1), traj.Q["wall"], rtol=1e-9, atol=1e-12)
    # energy balance: stored heat change = heat from the tubes + heat carried in by recycling
    stored = (traj.T[-1] - traj.T[0]) @ traj.capacity
    assert stored == pytest.approx(traj.Q["wall"][-1] + traj.Q["inflow"][-1], rel=1e-9)
    assert energy_balance(traj)[1] < 1e-9
    m = measure(traj)
    assert m["n_discharged"] == n_out and m["mass_flow"] > 0 and m["alpha_1"] > 0


def test_slit_narrower_than_a_particle_lets_nothing_through():
    # S = 0.6 d_p: with the softened contacts (200 N/m) a slit only ~10 % narrower than the
    # particles (S = 3.5 mm, d_p = 4 mm) lets some squeeze through under the bed's weight (the
    # lips' vertical support of a particle sinking between them is at most ~2 k (d - S)/2 x its
    # sine), so the test uses a clearly narrower slit
    s = _small(0.0024, 0.15)
    traj = simulate(MovingBed(s), progress=False)
    assert int(traj.records["n_out"][-1]) == 0
    assert traj.Q["inflow"][-1] == 0.0
    r = 0.5 * s.groups[0].diameter
    assert traj.position[:, :, 1].min() > -r  # nobody below the lips

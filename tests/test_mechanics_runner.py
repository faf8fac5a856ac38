"""Runner behaviour: tangential history across neighbour rebuilds, overflow handling, error
detection, contact output for the heat model, extra_update hook, float32, rotating drums."""

import math

import jax
import jax.numpy as jnp
import numpy as np
import pytest

from drumheat.devices import LENGTH_MULTIPLE, round_length
from drumheat.geometry import DrumShell
from drumheat.mechanics import (
    NonFiniteError,
    OverlapError,
    ParticleEscapeError,
    contact_params,
    make_dem,
    make_particles,
)
from drumheat.mechanics.analysis import angle_of_repose, center_of_mass
from drumheat.mechanics.pour import insertion_sites

R2D, RP = 0.025, 0.002


def _drum2d_positions(n, R=R2D, r=RP, spacing=2.2):
    sites = insertion_sites([DrumShell(R)], 2, spacing * r, 1.05 * r)
    sites = sites[np.argsort(sites[:, 1], kind="stable")]
    return sites[:n]


def _drum2d(n=40, rpm=30.0, **kw):
    part = make_particles(np.full(n, RP), 2700.0)
    p = contact_params(2e4, damping_ratio=0.3, friction=0.9, wall_friction=0.6)
    return make_dem(part, [DrumShell(R2D, rpm=rpm)], p, dim=2, **kw)


@pytest.fixture(scope="module")
def settled_2d():
    """40 aluminium spheres poured from a grid into a 50 mm drum turning at 30 rpm, 0.5 s."""
    dem = _drum2d()
    s = dem.run(dem.init(_drum2d_positions(40)), int(0.5 / dem.dt), chunk=20000)
    return dem, s


@pytest.mark.bitwise
def test_tangential_history_survives_neighbour_rebuilds(settled_2d):
    """Same trajectory with the normal skin (rare rebuilds) and a rebuild every step."""
    dem, s0 = settled_2d
    dem_always = _drum2d(always_rebuild=True)
    n = 3000
    a = dem.run_steps(s0._replace(n_rebuilds=jnp.asarray(0, jnp.int32)), n)
    start_b = dem_always.init(s0.position, s0.velocity, s0.angular_velocity, time=s0.time)
    # carry the springs over by pair identity (the fresh list has its own order)
    from drumheat.mechanics.neighbors import remap_pair_data
    start_b = start_b._replace(
        pair_spring=remap_pair_data(s0.nbrs.idx, s0.pair_spring, start_b.nbrs.idx, 40),
        wall_spring=s0.wall_spring, force=s0.force, torque=s0.torque)
    b = dem_always.run_steps(start_b, n)
    assert int(b.n_rebuilds) == n
    assert 0 < int(a.n_rebuilds) < n // 10
    # the springs matter: many contacts carry tangential history and some slide
    c = dem.contacts(a)
    springs = np.linalg.norm(np.asarray(a.pair_spring), axis=1)[np.asarray(c.pair_mask)]
    assert np.sum(springs > 1e-9) > 10, springs
    dx = np.max(np.abs(np.asarray(a.position) - np.asarray(b.position)))
    dw = np.max(np.abs(np.asarray(a.angular_velocity) - np.asarray(b.angular_velocity)))
    # pairs are kept in canonical order, so the two runs add the same forces in the same order:
    # identical to the last bit (observed 0.0); without the history remap they would differ
    # at once (next test), and this bed is chaotic (a 1e-15 m perturbation grows to 1e-6 m in
    # 100 steps), so any lost spring would show
    assert dx <= 1e-15
    assert dw <= 1e-12


def test_forgetting_history_would_change_the_trajectory(settled_2d):
    """Control for the test above: zeroing the springs at the start changes the result by far
    more than round-off, so the comparison is sensitive to lost history."""
    dem, s0 = settled_2d
    a = dem.run_steps(s0, 3000)
    b = dem.run_steps(s0._replace(pair_spring=jnp.zeros_like(s0.pair_spring),
                                  wall_spring=jnp.zeros_like(s0.wall_spring)), 3000)
    assert np.max(np.abs(np.asarray(a.position) - np.asarray(b.position))) > 1e-8


@pytest.mark.bitwise
def test_neighbour_overflow_is_reallocated_and_redone():
    """A list allocated for a dilute start (a poured grid: no pairs yet) overflows as the bed
    falls together; run() discards the chunk, reallocates and redoes it, and the result is the
    same as with a well-sized list from the start."""
    dem = _drum2d()
    grid = _drum2d_positions(40, spacing=2.6)  # 5.2 mm apart: beyond the 5 mm cutoff
    tiny = dem.init(grid, pair_capacity=1)  # one multiple of the slots: fewer than the bed's pairs
    big = dem.init(grid)
    assert tiny.nbrs.idx.shape[1] == LENGTH_MULTIPLE and big.nbrs.idx.shape[1] >= 160
    n = int(0.2 / dem.dt)
    out = dem.run(tiny, n, chunk=n // 2)
    ref = dem.run(big, n, chunk=n // 2)
    assert out.nbrs.idx.shape[1] > LENGTH_MULTIPLE
    assert not bool(out.nbrs.did_buffer_overflow)
    assert int(out.step) == n
    assert int(dem.contacts(out).pair_mask.sum()) > 30  # the settled bed has many contacts
    # never continued with missing contacts: same trajectory as the well-sized run
    assert np.max(np.abs(np.asarray(out.position) - np.asarray(ref.position))) <= 1e-15
    # while run_steps alone (no checks) does flag the overflow it cannot repair
    raw = dem.run_steps(tiny, n // 2)
    assert bool(raw.nbrs.did_buffer_overflow)


def test_default_capacity_is_that_of_a_dense_bed():
    """A dilute start gets the pair capacity of a dense bed of its particles (the mean count of
    neighbours at random close packing in 3D, at least the hexagonal first shell in 2D) with
    the allocation's head room; a start with more pairs sizes the list from its own. The slots
    come in whole multiples of drumheat.devices.LENGTH_MULTIPLE."""
    from drumheat.mechanics.neighbors import DENSE_FRACTION, dense_bed_pairs

    r = np.full(5, 0.004)
    c = 0.008 + 0.002
    assert dense_bed_pairs(r, c, 3) == pytest.approx(0.5 * (0.64 * (c / 0.004) ** 3 - 1))
    # sizes: <r^3>, so a few large spheres among small ones count as their volume says
    mix = np.array([0.002] * 4 + [0.004])
    assert dense_bed_pairs(mix, c, 3) == pytest.approx(
        0.5 * (DENSE_FRACTION[3] * c**3 / np.mean(mix**3) - 1))
    assert dense_bed_pairs(np.full(5, 0.002), 0.0048, 2) == 3.0  # six touching neighbours
    dem = _drum2d()
    grid = _drum2d_positions(40, spacing=2.6)  # no pairs within the cutoff yet
    floor = 1.5 * 40 * dense_bed_pairs(dem.particles.radius, dem.neighbor.cutoff, 2)
    assert dem.init(grid).nbrs.idx.shape[1] == round_length(int(np.ceil(floor)))
    packed = _drum2d_positions(40, spacing=1.0)  # closer than contact: more pairs than a bed
    count = dem.neighbor.count_pairs(jnp.asarray(packed))
    assert count * 1.5 > floor
    assert dem.init(packed).nbrs.idx.shape[1] == round_length(int(count * 1.5) + 1)


@pytest.mark.bitwise
def test_donated_chunks_run_the_same():
    """run(donate=True) (each chunk donates its start state, which is kept on the host for a
    redo): the same trajectory bit for bit as the plain path on the CPU, through an overflow and
    its redo; the caller's state and the states given to a callback stay usable."""
    dem = _drum2d()
    tiny = dem.init(_drum2d_positions(40, spacing=2.6), pair_capacity=1)
    n = int(0.2 / dem.dt)
    ref = dem.run(tiny, n, chunk=n // 4)
    out = dem.run(tiny, n, chunk=n // 4, donate=True)
    assert not tiny.position.is_deleted() and not tiny.nbrs.idx.is_deleted()
    assert out.nbrs.idx.shape == ref.nbrs.idx.shape
    for a, b in zip(jax.tree_util.tree_leaves(ref), jax.tree_util.tree_leaves(out)):
        np.testing.assert_array_equal(np.asarray(a), np.asarray(b))
    seen = []
    dem.run(out, 3 * 200, chunk=200, callback=seen.append, donate=True)
    assert len(seen) == 3 and not any(s.position.is_deleted() for s in seen)
    # an error after a donated chunk still carries the chunk's start (from the host copy)
    bad = out._replace(velocity=out.velocity.at[0, 0].set(jnp.nan))
    with pytest.raises(NonFiniteError) as err:
        dem.run(bad, 400, chunk=200, donate=True)
    assert int(err.value.state.step) == int(out.step)


def test_escape_nan_and_overlap_stop_the_run(settled_2d):
    dem, s0 = settled_2d
    # a particle outside the drum (inserted there, or tunnelled out): detected after the
    # first chunk (here one step; with longer chunks the shell would first throw it back and
    # the run would stop on the overlap check instead)
    pos = np.asarray(s0.position).copy()
    vel = np.asarray(s0.velocity).copy()
    pos[5] = [0.0, R2D + 0.01]
    vel[5] = [0.0, 1.0]
    with pytest.raises(ParticleEscapeError) as err:
        dem.run(s0._replace(position=jnp.asarray(pos), velocity=jnp.asarray(vel)), 10, chunk=1)
    assert err.value.state is not None and "particle 5" in str(err.value)
    assert int(err.value.state.step) == int(s0.step)
    # NaN
    vel = np.asarray(s0.velocity).copy()
    vel[3, 0] = np.nan
    with pytest.raises(NonFiniteError) as err:
        dem.run(s0._replace(velocity=jnp.asarray(vel)), 100, chunk=100)
    assert int(err.value.state.step) == int(s0.step)
    assert np.all(np.isfinite(np.asarray(err.value.state.position)))
    # overlap of 80 % of the radius between particles 0 and 1
    pos = np.asarray(s0.position).copy()
    pos[1] = pos[0] + np.array([1.2 * RP, 0.0])
    with pytest.raises(OverlapError) as err:
        dem.run(s0._replace(position=jnp.asarray(pos)), 10, chunk=10)
    assert "overlap" in str(err.value)


def test_contacts_for_the_heat_model(settled_2d):
    dem, s = settled_2d
    c = dem.contacts(s)
    m = np.asarray(c.pair_mask)
    i = np.asarray(c.pair_i)[m]
    j = np.asarray(c.pair_j)[m]
    assert np.all(i < j)
    assert len(set(zip(i.tolist(), j.tolist()))) == len(i)  # each contact once
    pos = np.asarray(s.position)
    d = np.linalg.norm(pos[j] - pos[i], axis=1)
    assert np.all(d < 2 * RP)
    # brute force: every touching pair is reported
    dd = np.linalg.norm(pos[:, None] - pos[None], axis=-1)
    iu = np.triu_indices(40, 1)
    assert np.sum(dd[iu] < 2 * RP) == len(i)
    # walls: (particle, wall id, mask) of the particles within r of the shell
    wm = np.asarray(c.wall_mask)
    touching = np.linalg.norm(pos, axis=1) > R2D - RP
    assert np.array_equal(np.sort(np.asarray(c.wall_particle)[wm]), np.flatnonzero(touching))
    assert np.all(np.asarray(c.wall_id)[wm] == 0)
    # fixed shapes (jit friendly): capacity and N x W
    assert c.pair_i.shape == s.nbrs.idx[0].shape and c.wall_mask.shape == (40,)


def test_extra_update_runs_contact_conduction_in_the_scan(settled_2d):
    """A thermal update plugged into the step: alpha A_p (T_j - T_i) over the contact pairs
    (Weigler digest [2.7]) conserves sum(m c T) and equalises temperatures."""
    _, s0 = settled_2d
    part = make_particles(np.full(40, RP), 2700.0)
    m_c = np.asarray(part.mass) * 900.0
    alpha_A = 105.0 * math.pi * (2 * RP) ** 2 / 4

    def conduction(T, state, contacts, dt):
        i, j, msk = contacts.pair_i, contacts.pair_j, contacts.pair_mask
        q = jnp.where(msk, alpha_A * (T[j] - T[i]), 0.0)  # W from j to i
        dQ = jax.ops.segment_sum(q, i, 40) - jax.ops.segment_sum(q, j, 40)
        return T + dt * dQ / m_c

    dem = _drum2d(extra_update=conduction)
    T0 = jnp.where(jnp.arange(40) < 20, 300.0, 340.0)
    s = dem.init(s0.position, s0.velocity, s0.angular_velocity, time=s0.time, extra=T0)
    s = dem.run(s, 20000, chunk=10000)
    T = np.asarray(s.extra)
    assert np.sum(m_c * T) == pytest.approx(np.sum(m_c * np.asarray(T0)), rel=1e-12)
    assert np.ptp(T) < 40.0


def test_float32_mechanics_stay_float32_and_agree_statistically(settled_2d):
    """dtype=float32: the mechanical state stays float32 (time float64). The bed is chaotic
    (a 1e-15 m perturbation reaches 1e-6 m in 100 steps), so float32 and float64 runs are
    compared after 1 step (round-off) and by the bed's centre of mass after 0.3 s."""
    dem, s0 = settled_2d
    dem32 = _drum2d(dtype=jnp.float32)
    s32 = dem32.init(s0.position, s0.velocity, s0.angular_velocity, time=s0.time)
    s64 = dem.init(s0.position, s0.velocity, s0.angular_velocity, time=s0.time)
    a = dem32.run_steps(s32, 1)
    b = dem.run_steps(s64, 1)
    assert np.max(np.abs(np.asarray(a.position) - np.asarray(b.position))) < 1e-8
    n = int(0.3 / dem.dt)
    s32 = dem32.run(s32, n, chunk=n)
    s64 = dem.run(s64, n, chunk=n)
    for leaf in (s32.position, s32.velocity, s32.angular_velocity, s32.force, s32.pair_spring):
        assert leaf.dtype == jnp.float32
    assert s32.time.dtype == jnp.float64
    c32 = center_of_mass(np.asarray(s32.position))
    c64 = center_of_mass(np.asarray(s64.position))
    assert c32[0] > 0.002 and c64[0] > 0.002
    assert np.max(np.abs(c32 - c64)) < 2e-3


def test_2d_drum_turns_stably_and_lifts_the_bed(settled_2d):
    """30 rpm, 2 revolutions: no error raised, the bed stays in motion and its centre of mass
    sits on the rising (+x) side of a counter-clockwise drum."""
    dem, s = settled_2d
    s = dem.run(s, int(4.0 / dem.dt), chunk=50000)
    com = center_of_mass(np.asarray(s.position))
    assert com[0] > 0.002
    assert angle_of_repose(np.asarray(s.position), RP) > 15.0
    assert dem.energies(s)["kinetic"] > 0


def _drum3d(n):
    """``(dem, sites, r, R, L)``: n spheres of r = 2 mm on a grid in a periodic slice (L = 16 mm)
    of a 50 mm drum turning at 60 rpm."""
    R, r, L = 0.025, 0.002, 0.016
    sites = insertion_sites([DrumShell(R)], 3, 2.2 * r, 1.05 * r, periodic_length=L)
    sites = sites[np.argsort(sites[:, 1], kind="stable")][:n]
    part = make_particles(np.full(len(sites), r), 2500.0)
    p = contact_params(2e4, damping_ratio=0.3, friction=0.9, wall_friction=0.6)
    dem = make_dem(part, [DrumShell(R, rpm=60.0)], p, dim=3, periodic_length=L)
    return dem, sites, r, R, L


def test_3d_periodic_drum_turns_stably():
    dem, sites, r, R, L = _drum3d(100)
    s = dem.run(dem.init(sites), int(2.0 / dem.dt), chunk=50000)  # 2 revolutions
    pos = np.asarray(s.position)
    assert np.all((pos[:, 2] >= 0) & (pos[:, 2] < L))
    assert np.all(np.linalg.norm(pos[:, :2], axis=1) < R)
    assert center_of_mass(pos)[0] > 0.002
    assert angle_of_repose(pos, r) > 15.0


def test_run_steps_equal_the_step_one_by_one():
    """``run_steps`` (runs of steps between rebuilds, each step's last half-kick carried to the
    next step) gives the states of :meth:`DEM.step` called step by step, bit for bit: 3D, spins,
    neighbour rebuilds on the way; and a run of no steps leaves the state as it is."""
    dem, sites = _drum3d(60)[:2]
    s0 = dem.run(dem.init(sites), 3000)  # falling onto the turning shell
    n = 400
    a = dem.run_steps(s0, n)
    b = s0
    for _ in range(n):
        b = dem.step(b)[0]
    assert int(a.n_rebuilds) - int(s0.n_rebuilds) >= 2
    assert int(b.n_rebuilds) == int(a.n_rebuilds)
    for name in ("position", "velocity", "angular_velocity", "force", "torque", "pair_spring",
                 "wall_spring"):
        np.testing.assert_array_equal(np.asarray(getattr(a, name)),
                                      np.asarray(getattr(b, name)), err_msg=name)
    assert float(jnp.max(jnp.abs(a.angular_velocity))) > 0.0
    z = dem.run_steps(s0, 0)
    for name in ("position", "velocity", "angular_velocity"):
        np.testing.assert_array_equal(np.asarray(getattr(z, name)), np.asarray(getattr(s0, name)))


def test_default_step_is_the_smaller_of_the_two_limits():
    """dt = min(safety_factor t_crit, dashpot limit); the dashpot limit of equal spheres with
    k_t = k_n is (sqrt(2) / (5 z zeta_t)) sqrt(m/k) (drumheat.models.soft_sphere)."""
    import warnings

    from drumheat.mechanics import DEMAccuracyWarning
    from drumheat.models.soft_sphere import STICKING_CONTACTS

    part = make_particles(np.full(3, 0.004), 2500.0)
    m, k = float(part.mass[0]), 2e3
    drum = [DrumShell(0.125, rpm=9.55)]
    damped = contact_params(k, damping_ratio=0.3, friction=0.9, wall_friction=0.6)
    dem = make_dem(part, drum, damped, dim=3, periodic_length=0.05, safety_factor=0.2)
    assert dem.dt == pytest.approx(math.sqrt(2) / (5 * STICKING_CONTACTS * 0.3)
                                   * math.sqrt(m / k), rel=1e-12)
    assert dem.dt / dem.t_crit == pytest.approx(0.0786, abs=1e-4)
    # no tangential dashpot, no friction to stick with, or no spin: t_crit governs
    for p, rotation in ((contact_params(k, damping_ratio=0.3, tangential_damping_ratio=0.0,
                                        wall_tangential_damping_ratio=0.0, friction=0.9,
                                        wall_friction=0.6), True),
                        (contact_params(k, damping_ratio=0.3, friction=0.0,
                                        wall_friction=0.0), True),
                        (damped, False)):
        d = make_dem(part, drum, p, dim=3, periodic_length=0.05, safety_factor=0.2,
                     rotation=rotation)
        assert d.dt == pytest.approx(0.2 * d.t_crit, rel=1e-12)
    with pytest.warns(DEMAccuracyWarning, match="dashpots"):
        make_dem(part, drum, damped, dim=3, periodic_length=0.05, dt=0.1 * dem.t_crit)
    with warnings.catch_warnings():
        warnings.simplefilter("error", DEMAccuracyWarning)
        make_dem(part, drum, damped, dim=3, periodic_length=0.05, dt=dem.dt)


@pytest.mark.parametrize("above", [False, True])
def test_resting_bed_is_stable_below_the_dashpot_limit(above):
    """70 spheres (4 mm, aluminium, damping 0.3, friction 0.9 / 0.6) deposited in layers into
    a 2D drum at rest, most with six neighbours: at the default step (the dashpot limit,
    0.079 t_crit) the forces are steady; at 0.1 t_crit (the scenes' step before the limit was
    known) the contacts chatter at half the step frequency, the period-2 component of the
    forces exceeding the particles' weights (the explicit dashpots overshoot on the spins,
    drumheat.models.soft_sphere.dashpot_time_step)."""
    import warnings

    from drumheat.mechanics.deposition import deposit_2d

    R, r, n = 0.025, 0.002, 70
    p = contact_params(2e4, damping_ratio=0.3, friction=0.9, wall_friction=0.6)
    packing = deposit_2d(np.full(n, 2 * r), np.zeros(n, int), 2 * R, seed=1)
    part = make_particles(np.full(n, r), 2700.0)
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")
        dem = make_dem(part, [DrumShell(R)], p, dim=2)
        if above:
            dem = make_dem(part, [DrumShell(R)], p, dim=2, dt=0.1 * dem.t_crit)
    state = dem.run(dem.init(np.asarray(packing.position)), int(round(0.3 / dem.dt)))
    forces = []
    for _ in range(16):
        forces.append(np.asarray(state.force, float))
        state = dem.run_steps(state, 1)
    period_2 = np.tensordot((-1.0) ** np.arange(16), np.array(forces), 1) / 16
    relative = np.linalg.norm(period_2, axis=1) / (np.asarray(part.mass) * 9.81)
    if above:
        assert relative.max() > 1.0
    else:
        assert relative.max() < 1e-6


def test_external_force_and_boundary_update_hooks():
    """A constant external force F accelerates a free sphere at g + F/m (velocity Verlet is
    exact for constant forces); a boundary hook that lifts particles below y = -0.01 m back
    to y = +0.01 m keeps them inside that band."""
    part = make_particles(np.full(1, RP), 2700.0)
    m = float(part.mass[0])
    p = contact_params(2e4)
    F = np.array([0.3 * m * 9.81, 0.5 * m * 9.81])
    box = (np.array([-1.0, -1.0]), np.array([1.0, 1.0]))
    dem = make_dem(part, [], p, dim=2, dt=1e-4, bounds=box,
                   external_force=lambda x, v, t, e: jnp.broadcast_to(jnp.asarray(F), x.shape))
    s = dem.run_steps(dem.init(np.zeros((1, 2))), 1000)
    t = float(s.time)
    a = np.array([0.0, -9.81]) + F / m
    np.testing.assert_allclose(np.asarray(s.position[0]), 0.5 * a * t**2, rtol=1e-9, atol=1e-12)

    def recycle(state):
        low = state.position[:, 1] < -0.01
        pos = state.position.at[:, 1].set(jnp.where(low, 0.01, state.position[:, 1]))
        vel = jnp.where(low[:, None], 0.0, state.velocity)
        return state._replace(position=pos, velocity=vel)

    dem = make_dem(part, [], p, dim=2, dt=1e-4, bounds=box, boundary_update=recycle)
    ys = []
    s = dem.init(np.zeros((1, 2)))
    for _ in range(20):
        s = dem.run_steps(s, 100)
        ys.append(float(s.position[0, 1]))
    assert min(ys) >= -0.01 - 1e-12 and max(ys) <= 0.01 + 1e-12
    assert any(y > 0.0 for y in ys[3:])  # it was lifted at least once

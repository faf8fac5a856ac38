"""Heat from friction and damping (drumheat.mechanics.dissipation, [heat.friction]).

The central check is the adiabatic box: particles thrown into a closed box come to rest, and
the heat their contacts generated equals the mechanical energy they lost (kinetic, rotational,
potential, elastic and the velocity-Verlet boundary term) to round-off.
"""

from __future__ import annotations

import sys
from pathlib import Path
from types import SimpleNamespace

import jax
import jax.numpy as jnp
import numpy as np
import pytest

from drumheat.geometry import Box
from drumheat.mechanics import (
    contact_params,
    make_dem,
    make_particles,
    restitution_from_damping_ratio,
)
from drumheat.mechanics.dissipation import SOURCES, ContactWork, FrictionHeat, step_heat
from drumheat.mechanics import cpu_kernel
from drumheat.scene import SceneError, load_scene

jax.config.update("jax_enable_x64", True)
sys.path.insert(0, str(Path(__file__).parent))
from test_cpu_kernel import _bed, needs_kernel  # noqa: E402


def _gather(extra, state, contacts, dt):
    d = contacts.dissipation
    return dict(E=extra["E"] + d.particle, W=extra["W"] + d.walls, S=extra["S"] + d.by_source)


def _box_run(dim, *, zeta=0.3, friction=0.5, rolling=0.05, t_end=0.06, n_side=4, seed=1,
             dt=None, heat=FrictionHeat(), kt=None, kernel="jax"):
    """Particles with random velocities in a closed box under gravity, the losses gathered
    every step: the mechanical energy lost, the heat gathered (J), the sources, the DEM, the
    final state and the kinetic energy thrown in. ``kernel``: make_dem's ``pair_kernel``."""
    rng = np.random.default_rng(seed)
    n = n_side * n_side
    r = 1e-3 * (1.0 + 0.2 * rng.random(n))
    g = np.linspace(0.003, 0.017, n_side)
    x = np.stack(np.meshgrid(g, g), -1).reshape(-1, 2)
    if dim == 3:
        x = np.concatenate([x, 0.004 + 0.002 * rng.random((n, 1))], axis=1)
    params = contact_params(1e4, kt=kt, kt_wall=kt, damping_ratio=zeta, friction=friction,
                            wall_friction=0.8 * friction, rolling_friction=rolling)
    gravity = np.zeros(dim)
    gravity[1] = -9.81
    box = Box((0.0,) * dim, (0.02, 0.03) + ((0.01,) * (dim == 3)))
    dem = make_dem(make_particles(r, 2500.0), [box], params, dim=dim, dt=dt, gravity=gravity,
                   extra_update=_gather, friction_heat=heat, pair_kernel=kernel)
    w0 = rng.normal(0.0, 50.0, (n,) if dim == 2 else (n, 3))
    state = dem.init(x, velocity=rng.normal(0.0, 0.3, x.shape), angular_velocity=w0,
                     extra=dict(E=jnp.zeros(n), W=jnp.zeros(()), S=jnp.zeros(len(SOURCES))))
    e0 = dem.energies(state)
    state = dem.run(state, int(round(t_end / dem.dt)))
    e1 = dem.energies(state)
    lost = (e0["total"] + e0["boundary"]) - (e1["total"] + e1["boundary"])
    heat_total = float(jnp.sum(state.extra["E"]) + state.extra["W"])
    return SimpleNamespace(lost=lost, heat=heat_total, sources=np.asarray(state.extra["S"]),
                           dem=dem, state=state, e_start=e0["kinetic"] + e0["rotational"])


@pytest.mark.parametrize("dim", [2, 3])
def test_adiabatic_box_heat_equals_lost_mechanical_energy(dim):
    b = _box_run(dim)
    lost, heat, sources, state = b.lost, b.heat, b.sources, b.state
    assert lost > 0
    # round-off of sums over ~1e4 steps of float64 numbers (measured 1e-14 .. 2e-13)
    assert abs(heat - lost) <= 1e-10 * lost
    # every source was at work, and they add up to the total
    assert np.all(sources[:3] > 0)
    assert abs(np.sum(sources) - heat) <= 1e-10 * heat
    # the walls (steel-like default split: half) took some, the particles the rest
    assert 0 < float(state.extra["W"]) < heat


@needs_kernel
@pytest.mark.parametrize("dim", [2, 3])
def test_adiabatic_box_with_the_cpu_kernel(dim):
    """The same balance with the C++ contact loop and its second pass (pair_kernel="cpu"),
    the losses split by conductivity (measured 3e-13 relative); over the first 0.005 s its
    heat equals the JAX kernel's per particle, per source and into the walls (measured 1e-14 of
    the largest particle's heat in 2D, 4e-17 in 3D)."""
    n = 16
    heat = FrictionHeat(conductivity=np.linspace(1.0, 3.0, n), wall_conductivity=15.0)
    b = _box_run(dim, heat=heat, kernel="cpu")
    assert b.lost > 0
    assert abs(b.heat - b.lost) <= 1e-10 * b.lost
    assert np.all(b.sources[:3] > 0)
    assert abs(np.sum(b.sources) - b.heat) <= 1e-10 * b.heat
    assert 0 < float(b.state.extra["W"]) < b.heat
    # the first 0.005 s with each kernel (later the collisions amplify their round-off
    # differences: 5e-4 of the heat after the 0.06 s above)
    j, c = (_box_run(dim, heat=heat, t_end=0.005, kernel=k) for k in ("jax", "cpu"))
    ej, ec = np.asarray(j.state.extra["E"]), np.asarray(c.state.extra["E"])
    assert j.heat > 0
    assert np.max(np.abs(ej - ec)) <= 1e-9 * np.max(np.abs(ej))
    np.testing.assert_allclose(c.sources, j.sources, rtol=0, atol=1e-9 * j.heat)
    assert float(c.state.extra["W"]) == pytest.approx(float(j.state.extra["W"]), rel=1e-9)


# One step of the two kernels: round-off, float32 1e-7 and float64 1e-16, times the growth of
# the sums and of the cancellation in D = -dt F.u - dU (measured, relative to the largest
# particle's heat: float32 6.6e-6 (2D) and 1.5e-5 (3D), float64 1.6e-14 and 5.7e-14; walls and
# sources relative to the largest source: float32 1.5e-6, float64 9e-15)
HEAT_REL = {jnp.float32: 1e-4, jnp.float64: 1e-11}
FH_CASES = [(2, jnp.float32, "half"), (2, jnp.float64, "conductivity"),
            (3, jnp.float32, "conductivity"), (3, jnp.float64, "half")]


@needs_kernel
@pytest.mark.filterwarnings("ignore::drumheat.mechanics.DEMAccuracyWarning")
@pytest.mark.parametrize("dim,dtype,partition", FH_CASES,
                         ids=[f"{d}d-{jnp.dtype(t).name}-{p}" for d, t, p in FH_CASES])
def test_cpu_kernel_heat_equals_the_jax_kernel(dim, dtype, partition):
    """One step of the dense bed of tests/test_cpu_kernel.py (two materials, rolling
    resistance, a rotating drum shell and a counter-rotating inner cylinder; random springs:
    some contacts slide, pairs that no longer touch release theirs): the heat of every
    particle, the walls' share and the heat by source of the C++ loop and its second pass equal
    the JAX kernel's."""
    def split(part):
        if partition == "half":
            return FrictionHeat()
        k = np.where(np.asarray(part.ptype) == 0, 1.0, 3.0)  # glass-like and steel-like
        return FrictionHeat(conductivity=k, wall_conductivity=15.0)

    jdem, st = _bed(dim, dtype, "jax", friction_heat=split)
    cdem, _ = _bed(dim, dtype, "cpu", friction_heat=split)
    a = jdem.step(st)[1].dissipation
    b = cdem.step(st)[1].dissipation
    rel = HEAT_REL[dtype]
    pa, pb = np.asarray(a.particle), np.asarray(b.particle)
    assert pa.dtype == pb.dtype == np.float64
    scale = np.max(np.abs(pa))
    src = np.max(np.abs(np.asarray(a.by_source)))
    assert np.max(np.abs(pa - pb)) <= rel * scale
    assert abs(float(a.walls - b.walls)) <= rel * src and float(a.walls) != 0
    assert np.max(np.abs(np.asarray(a.by_source - b.by_source))) <= rel * src
    assert np.all(np.asarray(b.by_source)[:3] > 0)  # damping, sliding and rolling at work


def test_elastic_contacts_generate_no_physical_heat():
    """Elastic normal springs only (no dashpots, no tangential springs, no rolling
    resistance): the continuous rates are zero exactly; what is left is the integrator's
    energy error, which vanishes as dt -> 0 (measured -2.9, -1.8, -0.56, -0.26 % of the energy
    thrown in at 0.2, 0.1, 0.05, 0.025 t_crit)."""
    t_crit = make_dem(make_particles([1e-3], 2500.0), [], contact_params(1e4), dim=2,
                      bounds=(np.zeros(2), np.ones(2))).t_crit
    rem = []
    for frac in (0.1, 0.025):
        b = _box_run(2, zeta=0.0, rolling=0.0, kt=0.0, t_end=0.03, dt=frac * t_crit)
        assert np.all(b.sources[:3] == 0.0)
        assert abs(b.heat - b.lost) <= 1e-12 * b.e_start
        rem.append(abs(b.sources[3]) / b.e_start)
    assert rem[0] < 0.05 and rem[1] < 0.5 * rem[0]


def test_integration_remainder_shrinks_with_the_step():
    """The continuous rates (damping, sliding, rolling) approach the exact discrete loss as
    dt -> 0: the remainder is first order in dt (halving dt halves it)."""
    rem = []
    t_crit = make_dem(make_particles([1e-3], 2500.0), [], contact_params(1e4), dim=2,
                      bounds=(np.zeros(2), np.ones(2))).t_crit
    for frac in (0.04, 0.02):
        b = _box_run(2, dt=frac * t_crit, t_end=0.04)
        rem.append(abs(b.sources[3]) / b.heat)
    assert rem[1] < 0.75 * rem[0]


def test_head_on_collision_heat_is_the_lost_kinetic_energy():
    """Two equal spheres meet head-on (no gravity, no walls): the heat is the kinetic energy
    lost, 1/2 m* v^2 (1 - e^2), with e of the continuous linear law (Schwager & Poeschel) as
    dt -> 0; half of it goes to each sphere."""
    zeta, v = 0.3, 0.2
    r = np.full(2, 1e-3)
    params = contact_params(1e4, damping_ratio=zeta, friction=0.5)
    p = make_particles(r, 2500.0)
    probe = make_dem(p, [], params, dim=2, gravity=np.zeros(2),
                     bounds=(np.array([-0.01, -0.01]), np.array([0.01, 0.01])))
    dem = make_dem(p, [], params, dim=2, gravity=np.zeros(2), dt=0.005 * probe.t_crit,
                   bounds=(np.array([-0.01, -0.01]), np.array([0.01, 0.01])),
                   extra_update=_gather, friction_heat=FrictionHeat())
    state = dem.init(np.array([[-1.2e-3, 0.0], [1.2e-3, 0.0]]),
                     velocity=np.array([[v, 0.0], [-v, 0.0]]),
                     extra=dict(E=jnp.zeros(2), W=jnp.zeros(()), S=jnp.zeros(len(SOURCES))))
    state = dem.run(state, int(round(2.5e-3 / dem.dt)))
    m_eff = 0.5 * float(p.mass[0])
    v_rel_out = float(state.velocity[1, 0] - state.velocity[0, 0])
    e_sim = v_rel_out / (2 * v)
    e_law = restitution_from_damping_ratio(zeta)
    E = np.asarray(state.extra["E"])
    expected = 0.5 * m_eff * (2 * v) ** 2 * (1 - e_law**2)
    assert e_sim == pytest.approx(e_law, rel=2e-3)  # the dashpot lag at 0.005 t_crit
    assert E.sum() == pytest.approx(0.5 * m_eff * (2 * v) ** 2 * (1 - e_sim**2), rel=1e-9)
    assert E.sum() == pytest.approx(expected, rel=5e-3)
    assert E[0] == pytest.approx(E[1], rel=1e-12)
    assert np.asarray(state.extra["S"])[0] == pytest.approx(E.sum(), rel=5e-3)  # damping


def test_conductivity_partition():
    """A pair's heat splits k_A/(k_A + k_B); a wall contact's k_p/(k_p + k_w)."""
    n = 2
    k = jnp.array([1.0, 3.0])
    fh = FrictionHeat(conductivity=k, wall_conductivity=1.0).checked(n)
    z2 = jnp.zeros((1, 2))
    zw = jnp.zeros((n, 1, 2))
    # one pair whose spring energy fell by 4 J with no work done: D = 4 J; particle 0 against
    # the wall lost 2 J the same way
    work = ContactWork(i=jnp.array([0]), j=jnp.array([1]), force=z2, lever_i=z2, lever_j=z2,
                       roll=None, elastic=jnp.array([-4.0]), rates=jnp.zeros((3, 1)),
                       wall_force=zw, wall_lever=zw, wall_velocity=zw, wall_roll=None,
                       wall_spin=None, wall_elastic=jnp.array([[-2.0], [0.0]]),
                       wall_rates=jnp.zeros((3, n, 1)))
    d = step_heat(fh, work, jnp.zeros((n, 2)), jnp.zeros(n), 1e-5)
    np.testing.assert_allclose(np.asarray(d.particle), [4 * 0.25 + 2 * 0.5, 4 * 0.75])
    assert float(d.walls) == pytest.approx(1.0)
    half = step_heat(FrictionHeat(), work, jnp.zeros((n, 2)), jnp.zeros(n), 1e-5)
    np.testing.assert_allclose(np.asarray(half.particle), [2.0 + 1.0, 2.0])
    with pytest.raises(ValueError, match="positive"):
        FrictionHeat(conductivity=jnp.array([1.0, 0.0]), wall_conductivity=1.0).checked(2)


def test_scene_friction_heat_books_and_balances(tmp_path):
    import drumheat as dh

    scene = load_scene("weigler-mixed", overrides=[
        "heat.friction.partition=conductivity", "dem.replay_after=none", "run.duration=0.5",
        "run.output_interval=0.25"])
    res = dh.run(scene, progress=False)
    ts, s = res.timeseries, res.summary
    assert s["energy_balance_rel_error"] < 1e-10
    assert s["heat_sources"] == ["friction"]
    # "auto": the C++ loop computes the losses too
    assert s["contact_backend"] == ("cpu" if cpu_kernel.available()[0] else "jax")
    if cpu_kernel.available()[0]:
        assert "contact_backend_note" not in s
    assert s["max_principle"]["bounds"][1] is None and s["max_principle"]["ok"]
    q = ts["Q_friction"].to_numpy()
    assert q[0] == 0 and np.all(np.diff(q) > 0)
    total = sum(ts[f"dissipated:{k}"].to_numpy() for k in SOURCES)
    np.testing.assert_allclose(total, q + ts["Q_friction_walls"].to_numpy(), rtol=1e-9,
                               atol=1e-15)


@pytest.mark.parametrize("overrides, key", [
    (["heat.friction.partition=half"], "heat.friction"),  # weigler-static: motion 'static'
])
def test_friction_heat_needs_the_dem(overrides, key):
    with pytest.raises(SceneError, match="motion model 'dem'"):
        load_scene("weigler-static", overrides=overrides)


def test_friction_heat_refuses_a_replay_phase():
    with pytest.raises(SceneError, match="replay_after"):
        load_scene("weigler-mixed", overrides=["heat.friction.partition=half"])


def _drum_script():
    import importlib.util

    path = Path(__file__).resolve().parents[1] / "scripts" / "friction_heat_drum.py"
    spec = importlib.util.spec_from_file_location("friction_heat_drum", path)
    mod = importlib.util.module_from_spec(spec)
    spec.loader.exec_module(mod)
    return mod


DRUM_300 = ["groups.0.count=300", "heat.friction.partition=conductivity",
            "dem.replay_after=none", "dem.record_interval=none", "run.duration=0.6",
            "run.output_interval=0.01"]


@pytest.mark.parametrize("backend", ["jax", pytest.param("cpu", marks=needs_kernel)])
def test_turning_drum_heat_equals_the_drive_work(backend):
    """The heat the contacts book in a turning drum equals the work of the turning shell
    (omega times its torque, from the bed's centre of mass, angular momentum and mechanical
    energy: scripts/friction_heat_drum.py), an independent route, on either contact kernel.
    300 beads of the 3D glass drum for 0.6 s, the window after 0.3 s, the bed sampled at every
    step and the change of the contacts' elastic energy and of the boundary term included
    (``step_balance``): measured -2.7e-6 (JAX) and 5.9e-6 (C++ loop) relative. Sampled at the
    0.01 s outputs without the elastic energy (``drum_balance``) the same window is off by
    up to 3e-4 on either kernel (the elastic energy grows by 2-4e-4 of the heat over the
    window, the trapezoid rule over the outputs is 1.7e-4 off): the script's docstring."""
    mod = _drum_script()
    scene = load_scene("glass-drum-3d", overrides=DRUM_300 + [f"dem.contact_backend={backend}"])
    b = mod.step_balance(scene, 0.3)
    assert b["backend"] == backend and b["steps"] > 19000
    assert b["heat"] > 0 and b["drive"] > 0
    assert b["heat"] == pytest.approx(b["drive"] + b["transient"] - b["stored"], rel=1e-4)


@needs_kernel
def test_cpu_kernel_heat_on_a_periodic_turning_drum_state():
    """One step of both kernels on a state of the 300-bead glass drum (the scene's DEM: the
    periodic drum axis, the turning DrumShell), shifted along the axis so that a particle with
    contacts crosses the periodic boundary in the step (its position before the drift,
    ``x - dt v``, lies outside [0, L)), once keeping the neighbour list and once with a rebuild
    (springs remapped): the heat of every particle, the walls' share and the sources agree.
    Measured 6.9e-12 of the largest particle's heat, walls 6e-14, sources 1.2e-12 (the
    overlaps, ~1e-6 m, of centre distances of 8e-3 m lose 13 bits: the forces of the two
    kernels differ by 7.5e-12)."""
    import dataclasses

    from drumheat.motion import make_motion

    jm, cm = (make_motion(load_scene("glass-drum-3d", overrides=DRUM_300 + [
        f"dem.contact_backend={b}"])) for b in ("jax", "cpu"))
    jd, cd = jm.dem, cm.dem
    assert (jm.contact_backend().backend, cm.contact_backend().backend) == ("jax", "cpu")
    st = jd.run(jm.initial_state(), 1500)  # the bed lifted by the shell, moving
    n, L, dt = st.position.shape[0], jm.periodic, jd.dt
    c = jd.contacts(st)  # (the scene's steps hand on no per-pair mask: contact_details)
    i, j, mask = (np.asarray(x) for x in (c.pair_i, c.pair_j, c.pair_mask))
    count = np.bincount(np.concatenate([i[mask], j[mask]]), minlength=n)
    vel = np.asarray(st.velocity)
    p = int(np.argmax(np.where(count >= 3, np.abs(vel[:, 2]), -1.0)))
    vz = vel[p, 2]
    pos = np.array(st.position)
    target = L - 0.5 * dt * vz if vz > 0 else -0.5 * dt * vz  # crosses z = L or z = 0
    pos[:, 2] = np.mod(pos[:, 2] + target - pos[p, 2], L)
    shifted = jd.reallocate(st._replace(position=jnp.asarray(pos)), st.nbrs.idx.shape[1])
    ref = shifted.nbrs.reference_position.at[0, 0].add(0.01)  # more than half the skin
    stale = shifted._replace(nbrs=dataclasses.replace(shifted.nbrs, reference_position=ref))
    for s, rebuilds in ((shifted, 0), (stale, 1)):
        (sa, a), (sb, b) = jd.step(s), cd.step(s)
        assert int(sa.n_rebuilds - s.n_rebuilds) == int(sb.n_rebuilds - s.n_rebuilds) == rebuilds
        z1 = float(sa.position[p, 2])
        assert 0.0 <= z1 < L and not 0.0 <= z1 - dt * float(sa.velocity[p, 2]) < L  # crossed
        i, j, mask = (np.asarray(x) for x in (a.pair_i, a.pair_j, jd.contacts(sa).pair_mask))
        z = np.asarray(sa.position[:, 2])
        ip, jp = np.minimum(i, n - 1), np.minimum(j, n - 1)
        across = mask & (np.abs(z[ip] - z[jp]) > 0.5 * L)  # contacts through the boundary
        assert np.sum(across & ((i == p) | (j == p))) >= 1 and np.sum(across) > 10
        assert int(np.sum(np.asarray(a.wall_mask))) > 20  # on the turning shell
        da, db = a.dissipation, b.dissipation
        pa, pb = np.asarray(da.particle), np.asarray(db.particle)
        assert np.max(np.abs(pa - pb)) <= 1e-10 * np.max(np.abs(pa))
        src = np.max(np.abs(np.asarray(da.by_source)))
        assert float(da.walls) > 0 and abs(float(da.walls - db.walls)) <= 1e-10 * src
        assert np.max(np.abs(np.asarray(da.by_source - db.by_source))) <= 1e-10 * src
        assert abs(float(np.sum(pa) - np.sum(pb))) <= 1e-10 * float(np.sum(pa) + da.walls)

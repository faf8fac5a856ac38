"""Per-particle results as a DataFrame (drumheat.particle_table, Result.particles) and the
per-particle heat flows that the ParaView export writes."""

import numpy as np
import pytest

import drumheat as dh
from drumheat.results.particles import heat_rates
from drumheat.results.plot import ParticleFrames


@pytest.fixture(scope="module")
def result():
    return dh.run(dh.load_scene("weigler-static", {"run.duration": 120.0,
                                                   "run.output_interval": 20.0}),
                  progress=False)


def test_one_row_per_particle_and_time(result):
    df = result.particles()
    n, n_out = result.summary["n_particles"], len(result.t)
    assert len(df) == n * n_out
    assert list(df.columns) == ["t", "particle", "group", "diameter", "T", "x", "y",
                                "heat_rate"]
    last = df[df.t == result.t[-1]].sort_values("particle")
    np.testing.assert_array_equal(last["T"], result.T[-1])
    np.testing.assert_array_equal(last[["x", "y"]].to_numpy(),
                                  result.trajectory.position[-1]
                                  if np.ndim(result.trajectory.position) == 3
                                  else result.trajectory.position)
    assert set(df.group.cat.categories) == {g.name for g in result.scene.groups}
    assert df.groupby("t").size().eq(n).all()
    assert np.array_equal(dh.particle_table(result, every=3).t.unique(), result.t[::3])
    with pytest.raises(ValueError, match="every"):
        dh.particle_table(result, every=0)


def test_heat_rates_close_the_energy_balance(result):
    """Summed over the bed and over an output interval, the heat flows are the heat the bed
    received from outside in that interval (the run's own accounts)."""
    q = heat_rates(ParticleFrames.from_result(result))
    assert np.all(np.isnan(q[0]))
    received = sum(result.trajectory.Q.values())
    dt = np.diff(result.t)
    np.testing.assert_allclose(q[1:].sum(axis=1) * dt, np.diff(received),
                               rtol=1e-6, atol=1e-9 * np.abs(received).max())
    # inside the bed heat flows from the warm to the cold particles in the first interval
    frames = ParticleFrames.from_result(result)
    warm = frames.group == frames.group_names.index("warm")
    assert q[1][warm].mean() < 0 < q[1][~warm].mean()


def test_read_from_the_result_folder(result, tmp_path):
    out = result.save(tmp_path / "res", figures=False)
    from_folder = dh.particle_table(out)
    from_memory = result.particles()
    np.testing.assert_allclose(from_folder[["t", "T", "x", "y"]].to_numpy(),
                               from_memory[["t", "T", "x", "y"]].to_numpy())
    np.testing.assert_allclose(from_folder.heat_rate.to_numpy(),
                               from_memory.heat_rate.to_numpy(), equal_nan=True)
    # the ParaView files carry the same heat flows
    from drumheat.results.vtk import export_vtk

    pvd = export_vtk(out, binary=False)
    last = sorted(pvd.parent.glob("particles_*.vtp"))[-1].read_text()
    assert 'Name="heat_rate"' in last
    block = last.split('Name="heat_rate"')[1].split(">", 1)[1].split("<", 1)[0]
    np.testing.assert_allclose(np.array(block.split(), float),
                               from_memory[from_memory.t == result.t[-1]].heat_rate, rtol=1e-6)


def test_heat_rates_need_a_lumped_scene():
    """Without a scene the capacities are unknown; with radial shells a particle's (surface)
    temperature is not its heat content: no heat_rate then."""
    import dataclasses

    scene = dh.load_scene("weigler-static")
    frames = ParticleFrames(t=np.array([0.0, 1.0]), T=np.full((2, 70), 300.0),
                            position=np.zeros((2, 70, 2)), diameter=np.full(70, 0.004),
                            group=np.zeros(70, int), group_names=["a"], scene=None, name="x")
    assert heat_rates(frames) is None
    q = heat_rates(dataclasses.replace(frames, scene=scene))
    assert q is not None and np.all(q[1] == 0.0)
    shells = scene.replace({"heat.internal": {"shells": 5}})
    assert heat_rates(dataclasses.replace(frames, scene=shells)) is None


def test_no_heat_rate_for_a_scene_of_other_particles():
    """A result folder whose scene.toml describes other particles (another count): the
    capacities are unknown, so no heat_rate (and the ParaView export still works)."""
    import dataclasses

    scene = dh.load_scene("weigler-static")  # 70 particles
    frames = ParticleFrames(t=np.array([0.0, 1.0]), T=np.full((2, 12), 300.0),
                            position=np.zeros((2, 12, 2)), diameter=np.full(12, 0.004),
                            group=np.zeros(12, int), group_names=["a"], scene=scene, name="x")
    assert heat_rates(frames) is None
    other_d = dataclasses.replace(frames, T=np.full((2, 70), 300.0),
                                  position=np.zeros((2, 70, 2)), diameter=np.full(70, 0.005),
                                  group=np.zeros(70, int))
    assert heat_rates(other_d) is None

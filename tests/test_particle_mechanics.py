"""Per-particle mechanics in the results (velocity, spin, force, contact numbers): what the
DEM writes at every output, read back from particles.npz, in the DataFrame and in ParaView."""

import xml.etree.ElementTree as ET

import numpy as np
import pytest
from scipy.spatial import cKDTree

import drumheat as dh
from drumheat.mechanics.analysis import PARTICLE_MECHANICS
from drumheat.results.plot import read_particles
from drumheat.results.vtk import export_vtk

G = 9.81


@pytest.fixture(scope="module")
def resting(tmp_path_factory):
    """weigler-mixed's bed in the drum at rest: 1 s after the settled packing, 4 outputs, the
    last 0.2 s replayed from the recording."""
    scene = dh.load_scene("weigler-mixed", {
        "drum.rpm": 0.0, "run.duration": 1.0, "run.output_interval": 0.2,
        "dem.record_interval": 0.05, "dem.replay_after": 0.8})
    out = tmp_path_factory.mktemp("mech") / "res"
    return dh.run(scene, out=out, progress=False), out


def _mass(result):
    return np.asarray(result.trajectory.mass)


def test_shapes_and_replayed_outputs(resting):
    result, _ = resting
    m = result.trajectory.mechanics
    n, n_out = result.summary["n_particles"], len(result.t)
    assert set(m) == set(PARTICLE_MECHANICS)
    assert m["velocity"].shape == m["force"].shape == (n_out, n, 2)
    assert m["angular_velocity"].shape == m["coordination"].shape == (n_out, n)
    coupled = result.t <= 0.8 + 1e-9
    for key, values in m.items():
        assert values.dtype == np.float32
        assert np.all(np.isfinite(values[coupled])), key
        assert np.all(np.isnan(values[~coupled])), key  # a replay has no mechanics


def test_resting_bed_is_in_static_equilibrium(resting):
    """Pair forces cancel in the sum; what remains, the walls' push, carries the bed's
    weight once it rests (Newton's third law and the equilibrium of a resting bed)."""
    result, _ = resting
    m = result.trajectory.mechanics
    weight = _mass(result).sum() * G
    for k in np.flatnonzero(np.isfinite(m["force"][:, 0, 0]))[1:]:
        total = m["force"][k].astype(float).sum(axis=0)
        # to the float32 round-off of the stored forces (at a step above the dashpot limit the
        # sum swung by 25 % of the weight from step to step: docs/models/dem-mechanics.md)
        assert total[1] == pytest.approx(weight, rel=1e-5)
        assert abs(total[0]) < 1e-5 * weight
        assert np.abs(m["velocity"][k]).max() < 1e-6 * np.sqrt(G * 0.004)


def test_contact_numbers_are_the_overlaps_of_the_positions(resting):
    """coordination / wall_contacts are the particles / walls each particle overlaps, counted
    independently from the written positions (pairs within float32 round-off of touching are
    allowed either way)."""
    result, _ = resting
    m = result.trajectory.mechanics
    d = np.asarray(result.trajectory.diameter)
    R = result.scene.drum.diameter / 2
    slack = 1e-5 * d.min()
    for k in np.flatnonzero(np.isfinite(m["coordination"][:, 0])):
        pos = np.asarray(result.trajectory.position[k], float)
        sure, maybe = np.zeros(len(d)), np.zeros(len(d))
        for i, j in cKDTree(pos).query_pairs(d.max() * 1.01):
            gap = np.linalg.norm(pos[i] - pos[j]) - (d[i] + d[j]) / 2
            for c, limit in ((sure, -slack), (maybe, slack)):
                if gap < limit:
                    c[i] += 1
                    c[j] += 1
        assert np.all(sure <= m["coordination"][k]) and np.all(m["coordination"][k] <= maybe)
        if k > 0:  # settled under its weight (the deposited packing at t = 0 just touches)
            assert sure.sum() > len(d)  # more than one contact per particle
        wall_gap = R - np.linalg.norm(pos, axis=1) - d / 2
        assert np.all((wall_gap < -slack) <= m["wall_contacts"][k])
        assert np.all(m["wall_contacts"][k] <= (wall_gap < slack))
        assert k == 0 or m["wall_contacts"][k].sum() > 0


def test_read_back_table_and_paraview(resting):
    result, out = resting
    frames = read_particles(out)
    for key, values in result.trajectory.mechanics.items():
        np.testing.assert_array_equal(frames.mechanics[key], values)
    df = dh.particle_table(out)
    for col in ("vx", "vy", "omega_z", "fx", "fy", "coordination", "wall_contacts"):
        assert col in df.columns
    last_coupled = df[np.isclose(df.t, 0.8)].sort_values("particle")
    np.testing.assert_array_equal(last_coupled["fy"],
                                  result.trajectory.mechanics["force"][4][:, 1])
    pvd = export_vtk(out)
    arrays = {a.get("Name"): a for a in ET.parse(pvd.parent / "particles_0004.vtp").iter(
        "DataArray")}
    assert arrays["angular_velocity"].get("NumberOfComponents") == "3"
    assert arrays["force"].get("NumberOfComponents") == "3"
    assert "coordination" in arrays and "wall_contacts" in arrays


def test_static_beds_have_none(tmp_path):
    result = dh.run(dh.load_scene("weigler-static", {"run.duration": 60.0}), progress=False)
    assert result.trajectory.mechanics == {}
    assert "vx" not in result.particles().columns

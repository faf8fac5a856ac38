"""ParaView export: files read back with VTK (points, arrays, times, walls)."""

import xml.etree.ElementTree as ET

import numpy as np
import pytest

from drumheat.cli import main
from drumheat.scene import load_scene
from drumheat.results.vtk import export_vtk, particle_velocities

vtk = pytest.importorskip("vtk", reason="the vtk package (test extra) reads the files back")
from vtk.util.numpy_support import vtk_to_numpy  # noqa: E402


def write_result(folder, dim=2, moving=True):
    """12 particles, 4 outputs at uneven times; positions move at a known velocity."""
    folder.mkdir(parents=True, exist_ok=True)
    over = {}
    if dim == 3:
        over = {"dim": 3, "drum.depth": 0.01, "packing.method": "file",
                "packing.file": "packing.npz"}
    scene = load_scene("weigler-static", overrides=over, check_files=False)  # a fake result
    n = 12
    rng = np.random.default_rng(0)
    pos0 = rng.uniform(-0.015, 0.015, size=(n, dim))
    if dim == 3:
        pos0[:, 2] = rng.uniform(0.002, 0.008, n)
    t = np.array([0.0, 10.0, 30.0, 60.0])
    v = np.zeros(dim)
    v[0], v[1] = 1e-4, -2e-4
    position = pos0[None] + t[:, None, None] * (v if moving else 0.0 * v)
    T = 300.0 + rng.uniform(0, 20, size=(len(t), n))
    diameter = np.where(np.arange(n) < 6, 0.004, 0.003)
    np.savez_compressed(folder / "particles.npz", t=t, T=T, group=(np.arange(n) >= 6).astype(int),
                        diameter=diameter, position=position,
                        group_names=np.array(["small", "big"]))
    (folder / "scene.toml").write_text(scene.to_toml())
    return dict(t=t, T=T, position=position, diameter=diameter, v=v, n=n)


def read_vtp(path):
    reader = vtk.vtkXMLPolyDataReader()
    reader.SetFileName(str(path))
    reader.Update()
    assert reader.GetErrorCode() == 0
    return reader.GetOutput()


def point_array(poly, name):
    arr = poly.GetPointData().GetArray(name)
    assert arr is not None, f"point array {name!r} missing"
    return vtk_to_numpy(arr)


def read_pvd(path):
    root = ET.parse(path).getroot()
    assert root.get("type") == "Collection"
    return [(float(d.get("timestep")), path.parent / d.get("file"))
            for d in root.iter("DataSet")]


@pytest.mark.parametrize("binary", [True, False])
def test_particles_read_back(tmp_path, binary):
    ref = write_result(tmp_path / "res")
    pvd = export_vtk(tmp_path / "res", binary=binary)
    assert pvd == tmp_path / "res" / "vtk" / "particles.pvd"
    entries = read_pvd(pvd)
    np.testing.assert_allclose([t for t, _ in entries], ref["t"])
    for k, (t, f) in enumerate(entries):
        poly = read_vtp(f)
        assert poly.GetNumberOfPoints() == ref["n"]
        assert poly.GetNumberOfVerts() == ref["n"]
        pts = vtk_to_numpy(poly.GetPoints().GetData())
        np.testing.assert_allclose(pts[:, :2], ref["position"][k])
        np.testing.assert_allclose(pts[:, 2], 0.0)
        np.testing.assert_allclose(point_array(poly, "radius"), ref["diameter"] / 2)
        np.testing.assert_allclose(point_array(poly, "temperature"), ref["T"][k])
        np.testing.assert_array_equal(point_array(poly, "group"), np.arange(12) >= 6)
        np.testing.assert_array_equal(point_array(poly, "id"), np.arange(12))
        vel = point_array(poly, "velocity")
        assert vel.shape == (12, 3)
        np.testing.assert_allclose(vel, np.broadcast_to([1e-4, -2e-4, 0.0], (12, 3)),
                                   atol=1e-15)
        time = vtk_to_numpy(poly.GetFieldData().GetArray("TIME"))
        assert time[0] == pytest.approx(t)
    names = read_vtp(entries[0][1]).GetFieldData().GetAbstractArray("group_names")
    assert [names.GetValue(i) for i in range(names.GetNumberOfValues())] == ["small", "big"]


def test_resting_bed_has_zero_velocity_and_walls_2d(tmp_path):
    write_result(tmp_path / "res", moving=False)
    pvd = export_vtk(tmp_path / "res", out_dir=tmp_path / "pv")
    for _, f in read_pvd(pvd):
        np.testing.assert_array_equal(point_array(read_vtp(f), "velocity"), 0.0)
    walls = read_vtp(tmp_path / "pv" / "walls.vtp")
    pts = vtk_to_numpy(walls.GetPoints().GetData())
    assert walls.GetNumberOfLines() == 1 and walls.GetNumberOfPolys() == 0
    np.testing.assert_allclose(np.hypot(pts[:, 0], pts[:, 1]), 0.025)
    np.testing.assert_allclose(pts[:, 2], 0.0)


def test_walls_3d_cylinder_surface(tmp_path):
    ref = write_result(tmp_path / "res", dim=3)
    pvd = export_vtk(tmp_path / "res", n_segments=64)
    poly = read_vtp(read_pvd(pvd)[2][1])
    np.testing.assert_allclose(vtk_to_numpy(poly.GetPoints().GetData()), ref["position"][2])
    walls = read_vtp(pvd.parent / "walls.vtp")
    assert walls.GetNumberOfPolys() == 64
    assert walls.GetBounds() == pytest.approx((-0.025, 0.025, -0.025, 0.025, 0.0, 0.01),
                                              abs=1e-12)


def test_velocity_on_uneven_grid():
    t = np.array([0.0, 1.0, 3.0])
    x = (t**2)[:, None, None] * np.ones((1, 2, 2))  # x = t^2: second-order exact
    v = particle_velocities(t, x)
    np.testing.assert_allclose(v[1], 2.0)
    assert particle_velocities([5.0], x[:1]).tolist() == np.zeros((1, 2, 2)).tolist()


def test_cli_export_vtk(tmp_path, capsys):
    write_result(tmp_path / "res")
    assert main(["export-vtk", str(tmp_path / "res"), "--out", str(tmp_path / "o")]) == 0
    assert "particles.pvd" in capsys.readouterr().out
    assert len(read_pvd(tmp_path / "o" / "particles.pvd")) == 4
    assert main(["export-vtk", str(tmp_path / "nothing")]) == 2
    assert "does not exist" in " ".join(capsys.readouterr().err.split())

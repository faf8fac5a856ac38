"""The sectional-drum DEM scene (issue 7): drum internals, per-surface heat, contact-length
measurement (herz-sectional-drum.md)."""

import math

import numpy as np
import pytest

from drumheat.geometry.walls import DrumShell, InnerCylinder, RadialPlate
from drumheat.mechanics.analysis import section_contact_lengths
from drumheat.mechanics.pour import section_of
from drumheat.assemble import drum_walls
from drumheat.models.sectional_drum import bed_polygon, contact_lengths
from drumheat.scene import SceneError, builtin_scenes, load_scene

SCENE = "herz-sectional-drum"


def test_scene_is_listed_and_builds_ten_walls():
    assert SCENE in builtin_scenes() and builtin_scenes()[SCENE]
    scene = load_scene(SCENE)
    d = scene.drum
    assert d.sections == 8 and d.rpm == -1.0
    assert d.inner_diameter / d.diameter == pytest.approx(0.175)
    walls = drum_walls(scene)
    assert len(walls) == 10
    assert isinstance(walls[0], DrumShell) and walls[0].radius == pytest.approx(0.15)
    assert isinstance(walls[1], InnerCylinder) and walls[1].radius == pytest.approx(0.02625)
    plates = walls[2:]
    assert all(isinstance(p, RadialPlate) for p in plates)
    for j, p in enumerate(plates):  # plate j at 180 - 45 j deg: section j at Herz delta = 45 j
        assert math.degrees(p.phase) == pytest.approx(180.0 - 45.0 * j)
        assert p.r_inner == pytest.approx(0.02625) and p.r_outer == pytest.approx(0.15)
        assert p.rpm == -1.0
    # each heated surface has its own wall id, in the order of heated_surfaces()
    names = [s for s, _ in d.heated_surfaces()]
    assert names == ["shell", "inner", "plates"]
    assert [w.wall_id for w in walls] == [0, 1] + [2] * 8
    assert [w.temperature for w in walls[:3]] == [d.wall_temperature, d.inner_temperature,
                                                  d.plate_temperature]
    # the plates turn clockwise: plate 0 (at 180 deg) moves up, towards smaller polar angles
    assert float(plates[0].angle(7.5)) == pytest.approx(math.radians(180.0 - 45.0))


def test_plain_drum_keeps_one_wall_account():
    from drumheat.assemble import thermal_model

    scene = load_scene("weigler-glass-drum-9.55")
    assert scene.drum.heated_surfaces() == (("wall", "drum.wall_temperature"),)
    model, _ = thermal_model(scene)
    assert model.accounts == ("wall",)
    assert drum_walls(scene)[0].wall_id == 0 and len(drum_walls(scene)) == 1


def test_internals_are_validated():
    with pytest.raises(SceneError, match="motion model 'dem'"):
        load_scene("weigler-static", {"drum.sections": 8})
    with pytest.raises(SceneError, match="drum.plate_temperature"):
        load_scene(SCENE, {"drum.sections": 0})
    with pytest.raises(SceneError, match="drum.inner_diameter"):
        load_scene(SCENE, {"drum.inner_diameter": 0.3})
    with pytest.raises(SceneError, match="packing.method"):
        load_scene(SCENE, {"packing.method": "deposition"})


# ---- the measurement on a synthetic bed --------------------------------------------------


def _seg_dist(p, a, b):
    ab = b - a
    t = np.clip(((p - a) @ ab) / (ab @ ab), 0, 1)
    return np.hypot(*(p - (a + t[:, None] * ab)).T)


def synthetic_bed(delta, *, R1, R2, fill, gamma, d):
    """Discs of diameter d filling the model's bed polygon densely: one disc in every corner,
    a layer along the whole outline (walls and free surface), a hexagonal lattice inside."""
    from matplotlib.path import Path
    from scipy.spatial import cKDTree

    poly = bed_polygon(delta, R1=R1, R2=R2, fill=fill, gamma_deg=gamma, n_arc=400)
    r, m = 0.5 * d, len(poly)
    sgn = 1.0 if np.sum(poly[:, 0] * np.roll(poly[:, 1], -1)
                        - np.roll(poly[:, 0], -1) * poly[:, 1]) > 0 else -1.0
    pts = []
    for i in range(m):  # corner discs, tangent to both edges
        e1 = poly[i - 1] - poly[i]
        e2 = poly[(i + 1) % m] - poly[i]
        e1, e2 = e1 / np.hypot(*e1), e2 / np.hypot(*e2)
        th = math.acos(np.clip(e1 @ e2, -1, 1))
        if th < math.radians(170) and sgn * (e2[0] * e1[1] - e2[1] * e1[0]) > 0:
            bis = (e1 + e2) / np.hypot(*(e1 + e2))
            pts.append(poly[i] + bis * 1.001 * r / math.sin(th / 2))
    closed = np.vstack([poly, poly[:1]])
    per = np.concatenate([[0], np.cumsum(np.hypot(*np.diff(closed, axis=0).T))])
    for s in np.arange(0.5 * d, per[-1], 1.02 * d):  # the outline layer
        i = np.searchsorted(per, s) - 1
        a, b = poly[i], poly[(i + 1) % m]
        e = (b - a) / np.hypot(*(b - a))
        pts.append(a + (s - per[i]) * e + 1.001 * r * sgn * np.array([-e[1], e[0]]))
    path = Path(poly)

    def inside(X, clear):
        ok = path.contains_points(X)
        for i in range(m):
            ok &= _seg_dist(X, poly[i], poly[(i + 1) % m]) >= clear
        return ok

    P = np.array(pts)
    P = P[inside(P, 0.99 * r)]
    keep = []
    for p in P:
        if all(np.hypot(*(p - q)) >= 0.999 * d for q in keep):
            keep.append(p)
    P = np.array(keep)
    lo, hi = poly.min(0), poly.max(0)
    ys = np.arange(lo[1], hi[1], d * math.sqrt(3) / 2)
    H = np.array([(x + (0.5 * d if k % 2 else 0.0), y) for k, y in enumerate(ys)
                  for x in np.arange(lo[0], hi[0], d)])
    H = H[inside(H, r)]
    H = H[cKDTree(P).query(H)[0] >= d]
    return np.vstack([P, H])


@pytest.mark.parametrize("delta", [5.0, 30.0, 60.0, 100.0, 150.0, 200.0, 250.0, 300.0, 340.0])
def test_measured_lengths_match_the_model_on_a_synthetic_bed(delta):
    R1, R2, fill, gamma, d = 0.15, 0.02625, 0.3, 25.0, 0.002
    X = synthetic_bed(delta, R1=R1, R2=R2, fill=fill, gamma=gamma, d=d)
    # the section under test is section 0; the other sections are empty
    m = section_contact_lengths(X, 0.5 * d, R1=R1, R2=R2, n_sections=8,
                                plate_angle=math.pi - math.radians(delta))
    assert m["delta_deg"][0] == pytest.approx(delta)
    assert m["n"][0] == len(X) and np.all(m["n"][1:] == 0)
    cl = contact_lengths(delta, R1=R1, R2=R2, fill=fill, gamma_deg=gamma)
    for k in ("P1", "P2", "Wo", "Wi", "l_SG"):
        assert m[k][0] == pytest.approx(float(getattr(cl, k)), abs=d), k
    assert m["gamma_deg"][0] == pytest.approx(gamma, abs=1.5)


# ---- a very short run --------------------------------------------------------------------


@pytest.fixture(scope="module")
def short_run():
    import drumheat

    return drumheat.run(load_scene(SCENE, SHORT), progress=False)


#: few particles, softer contacts and a coarser step: this checks the plumbing, not the
#: mechanics (seconds instead of minutes)
SHORT = {"groups.0.count": 80, "run.duration": 0.1, "run.output_interval": 0.05,
         "dem.stiffness": 25.0, "dem.safety_factor": 0.2, "packing.surface_angle": 0.0}


def test_a_run_into_a_folder_gives_the_same_numbers(short_run, tmp_path):
    """With a result folder (as ``drumheat run`` runs) the chunks advance in place on the CPU
    and their start is kept on disk (drumheat.runner.spill); the state of this scene's heat
    model holds weakly typed coefficients (Schluender's), which once stopped such a run at its
    first chunk. Bit for bit the numbers of the run without a folder."""
    import drumheat

    res = drumheat.run(load_scene(SCENE, SHORT), out=tmp_path / "run", progress=False)
    assert (tmp_path / "run" / "summary.json").is_file()
    np.testing.assert_array_equal(res.T, short_run.T)
    np.testing.assert_array_equal(res.trajectory.position, short_run.trajectory.position)
    assert res.timeseries.equals(short_run.timeseries)


def test_short_run_stays_in_sections_and_books_heat_per_surface(short_run):
    res = short_run
    scene = res.scene
    traj = res.trajectory
    n_sec = scene.drum.sections
    omega = 2 * math.pi * scene.drum.rpm / 60
    sec0 = section_of(traj.position[0], n_sec, math.pi)
    assert np.all(np.bincount(sec0, minlength=n_sec) == 10)  # the same load in every section
    for t, p in zip(traj.t, traj.position):
        assert np.array_equal(section_of(p, n_sec, math.pi + omega * t), sec0)
    ts = res.timeseries
    for col in ("Q_wall", "Q_wall:shell", "Q_wall:inner", "Q_wall:plates"):
        assert col in ts.columns
    # hot plates and inner cylinder touch the bed: heat flows in through them
    assert ts["Q_wall:plates"].iloc[-1] > 0 and ts["Q_wall:inner"].iloc[-1] > 0
    assert ts["Q_wall:shell"].iloc[-1] > 0
    assert ts["Q_wall"].iloc[-1] == pytest.approx(
        ts[["Q_wall:shell", "Q_wall:inner", "Q_wall:plates"]].iloc[-1].sum())
    assert res.summary["energy_balance_rel_error"] < 1e-9
    assert ts["T_mean"].iloc[-1] > ts["T_mean"].iloc[0]

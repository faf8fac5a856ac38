"""What the mechanics' float type resolves: drumheat.mechanics.precision, the warning of
make_dem and the summary of a scene (docs/performance.md, precision)."""

import warnings

import jax.numpy as jnp
import numpy as np
import pytest

import drumheat  # noqa: F401
from drumheat.geometry import DrumShell
from drumheat.mechanics import DEMAccuracyWarning, contact_params, make_dem, make_particles
from drumheat.mechanics.precision import position_resolution
from drumheat.motion import make_motion
from drumheat.scene import load_scene

R, K, RHO, RP = 0.125, 1.0e5, 2500.0, 0.004


def _drum(length, dtype, n=2, gravity=None):
    part = make_particles(np.full(n, RP), RHO)
    params = contact_params(K, restitution=0.5, friction=0.5)
    with warnings.catch_warnings(record=True) as caught:
        warnings.simplefilter("always")
        dem = make_dem(part, [DrumShell(R)], params, dim=3, periodic_length=length, dtype=dtype,
                       gravity=gravity)
    return dem, [w for w in caught if issubclass(w.category, DEMAccuracyWarning)]


def test_resolution_is_the_spacing_at_the_largest_coordinate():
    res = position_resolution(jnp.float32, [-0.13, -0.13, 0.0], [0.13, 0.12, 1.3], 1.5e-5,
                              6.7e-4, 1.0e5, [0.0, -9.81, 0.0])
    assert res.dtype == "float32"
    np.testing.assert_array_equal(res.spacing, [np.spacing(np.float32(0.13)),
                                                np.spacing(np.float32(0.13)),
                                                np.spacing(np.float32(1.3))])
    assert res.spacing[2] == 2.0**-23  # 1.3 lies in [1, 2): the spacing 2^-23
    assert res.weight_overlap == pytest.approx(6.7e-4 * 9.81 / 1.0e5)
    np.testing.assert_allclose(res.slowest_speed, res.spacing / 3.0e-5)
    assert res.spacing_over_weight_overlap == pytest.approx(2.0**-23 / (6.7e-4 * 9.81 / 1e5))
    s = res.summary()
    assert s["mechanics"] == "float32" and s["position_spacing_m"][2] == 2.0**-23
    # float64: 2^29 times finer; without gravity there is no weight to compare with
    res64 = position_resolution(jnp.float64, [0, 0, 0], [1.3, 1.3, 1.3], 1.5e-5, 6.7e-4, 1e5,
                                [0.0, 0.0, 0.0])
    assert res64.spacing[0] == 2.0**-52 and res64.weight_overlap is None
    assert res64.spacing_over_weight_overlap is None


def test_make_dem_warns_where_float32_cannot_resolve_a_resting_contact():
    """The drum slice of glass-drum-3d: m g / k_n = 6.6e-8 m for 8 mm glass at k_n = 1e5 N/m;
    float32's spacing reaches it at a periodic length of 1 m (2^-23 m above 1 m), not at
    0.26 m (N = 10 000) nor in float64."""
    dem, caught = _drum(1.3, jnp.float32)
    assert len(caught) == 1
    msg = str(caught[0].message)
    assert "1.2e-07 m" in msg and "along z" in msg and "float64" in msg
    assert dem.position_resolution().spacing_over_weight_overlap == pytest.approx(
        2.0**-23 / dem.position_resolution().weight_overlap)
    for length, dtype in ((0.26, jnp.float32), (1.3, jnp.float64)):
        _, caught = _drum(length, dtype)
        assert caught == []
    _, caught = _drum(1.3, jnp.float32, gravity=[0.0, 0.0, 0.0])  # nothing rests: no warning
    assert caught == []


@pytest.mark.parametrize("factor, moves", [(0.9, False), (1.1, True)])
def test_a_particle_below_the_slowest_speed_does_not_move(factor, moves):
    """Along the periodic axis at z = 1.2 m (float32 spacing 2^-23 m): a particle slower than
    spacing / (2 dt) keeps its coordinate step after step; a little faster, it moves by one
    spacing per step (about twice its speed: the drift is rounded too)."""
    dem, _ = _drum(1.3, jnp.float32, n=1, gravity=[0.0, 0.0, 0.0])
    v = factor * float(dem.position_resolution().slowest_speed[2])
    state = dem.init(np.array([[0.0, -0.05, 1.2]]), velocity=np.array([[0.0, 0.0, v]]))
    out = dem.run(state, 50, chunk=50)
    dz = float(out.position[0, 2]) - float(state.position[0, 2])
    if moves:
        assert dz == pytest.approx(50 * 2.0**-23)
    else:
        assert dz == 0.0
    assert float(out.velocity[0, 2]) == pytest.approx(v)  # the velocity itself is kept


def test_summary_says_what_the_mechanics_resolve():
    over = {"groups.0.count": 500, "drum.depth": 1.3, "dem.precision": "float32"}
    with pytest.warns(DEMAccuracyWarning, match="resolve positions"):
        motion = make_motion(load_scene("glass-drum-3d", over))
    info = motion.backend_info()["precision"]
    assert info["mechanics"] == "float32"
    assert info["spacing_over_weight_overlap"] > 1.0
    assert info["position_spacing_m"][2] == 2.0**-23
    info = make_motion(load_scene("glass-drum-3d")).backend_info()["precision"]
    assert info["mechanics"] == "float64" and info["spacing_over_weight_overlap"] < 1e-8



def test_several_dems_say_it_once():
    """A scene builds several DEMs in the same slice (the pour's, the run's), from different
    places: Python's default filter shows the one message once (it is raised at make_dem's own
    line)."""
    part = make_particles(np.full(2, RP), RHO)
    params = contact_params(K, restitution=0.5, friction=0.5)
    with warnings.catch_warnings(record=True) as caught:
        warnings.simplefilter("default")
        make_dem(part, [DrumShell(R)], params, dim=3, periodic_length=1.3, dtype=jnp.float32)
        make_dem(part, [DrumShell(R)], params, dim=3, periodic_length=1.3, dtype=jnp.float32)
    assert len([w for w in caught if issubclass(w.category, DEMAccuracyWarning)]) == 1

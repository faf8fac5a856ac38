"""What the mechanics' float type resolves: drumheat.mechanics.precision, the warning of
make_dem and the summary of a scene (docs/performance.md, precision)."""

import warnings

import jax.numpy as jnp
import numpy as np
import pytest

import drumheat  # noqa: F401
from drumheat.geometry import DrumShell
from drumheat.mechanics import DEMAccuracyWarning, contact_params, make_dem, make_particles
from drumheat.mechanics.precision import fold_length, position_resolution
from drumheat.motion import make_motion
from drumheat.scene import load_scene

R, K, RHO, RP = 0.125, 1.0e5, 2500.0, 0.004


def _drum(length, dtype, n=2, gravity=None, position_dtype=None):
    part = make_particles(np.full(n, RP), RHO)
    params = contact_params(K, restitution=0.5, friction=0.5)
    with warnings.catch_warnings(record=True) as caught:
        warnings.simplefilter("always")
        dem = make_dem(part, [DrumShell(R)], params, dim=3, periodic_length=length, dtype=dtype,
                       gravity=gravity, position_dtype=position_dtype)
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
    assert "1.2e-07 m" in msg and "along z" in msg and "float64" in msg and "\"mixed\"" in msg
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
    with pytest.warns(DEMAccuracyWarning, match="resolves positions"):
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


def test_fold_length_divides_the_period():
    """Mixed precision folds the periodic axis to L / k, at least the cross-section's largest
    coordinate and four cutoffs; a slice shorter than twice that is not folded."""
    assert fold_length(1.3, 0.129, 0.01) == pytest.approx(0.13)  # k = 10
    assert fold_length(26.0, 0.129, 0.01) == pytest.approx(26.0 / 201)
    assert fold_length(1.3, 0.129, 0.05) == pytest.approx(1.3 / 6)  # four cutoffs: 0.2 m
    assert fold_length(0.2, 0.129, 0.01) is None and fold_length(None, 0.129, 0.01) is None


def _pair_along_the_axis(dtype, position_dtype, z0, overlap):
    """The normal force of two particles touching along the periodic axis at z0 of a 1.3 m
    slice (no gravity, at rest), and the DEM."""
    dem, _ = _drum(1.3, dtype, gravity=[0.0, 0.0, 0.0], position_dtype=position_dtype)
    pos = np.array([[0.0, -0.05, z0], [0.0, -0.05, z0 + 2 * RP - overlap]])
    state = dem.init(pos)
    return float(np.asarray(state.force, np.float64)[1, 2]), dem


def test_mixed_precision_resolves_a_contact_far_along_the_axis():
    """At z = 1.2 m float32's spacing is 1.2e-7 m, a quarter of a typical overlap of 5e-7 m:
    the rounded positions give a normal force off by up to k_n times that. Mixed precision
    reads the positions folded to 0.13 m and rounded there: the error is bounded by k_n times
    the spacing at the fold (1.5e-8 m) plus float32's arithmetic on a 8 mm separation."""
    z0, overlap = 1.2 + 3.3e-8, 5e-7  # 3.3e-8: a coordinate that float32 must round
    f64, _ = _pair_along_the_axis(jnp.float64, None, z0, overlap)
    mixed, dem = _pair_along_the_axis(jnp.float32, jnp.float64, z0, overlap)
    f32, _ = _pair_along_the_axis(jnp.float32, None, z0, overlap)
    assert f64 == pytest.approx(K * overlap, rel=1e-6)  # at rest: the spring alone
    bound = K * (np.spacing(np.float32(dem.fold_length)) + 2 * np.spacing(np.float32(2 * RP)))
    assert abs(mixed - f64) <= bound
    # float32 here: the two coordinates' rounding, exactly as numpy rounds them
    d32 = float(np.float32(z0 + 2 * RP - overlap) - np.float32(z0))
    assert abs(f32 - K * (2 * RP - d32)) <= K * 2 * np.spacing(np.float32(2 * RP))
    assert abs(f32 - f64) > 2 * bound  # where float32 is off, mixed is not


def test_mixed_precision_moves_a_slow_particle():
    """The particle of test_a_particle_below_the_slowest_speed_does_not_move at 0.9 times
    float32's slowest speed: with the positions in float64 it drifts dt v per step."""
    dem32, _ = _drum(1.3, jnp.float32, n=1, gravity=[0.0, 0.0, 0.0])
    v = 0.9 * float(dem32.position_resolution().slowest_speed[2])
    dem, _ = _drum(1.3, jnp.float32, n=1, gravity=[0.0, 0.0, 0.0], position_dtype=jnp.float64)
    state = dem.init(np.array([[0.0, -0.05, 1.2]]), velocity=np.array([[0.0, 0.0, v]]))
    out = dem.run(state, 50, chunk=50)
    assert out.position.dtype == jnp.float64 and out.velocity.dtype == jnp.float32
    dz = float(out.position[0, 2]) - float(state.position[0, 2])
    assert dz == pytest.approx(50 * dem.dt * float(np.float32(v)), rel=1e-6)


def test_mixed_precision_in_a_scene():
    """``[dem] precision = "mixed"``: no warning in the 1.3 m slice where float32 warns; the
    summary gives the folded axis's spacing and float64's drift."""
    over = {"groups.0.count": 500, "drum.depth": 1.3, "dem.precision": "mixed"}
    with warnings.catch_warnings():
        warnings.simplefilter("error", DEMAccuracyWarning)
        motion = make_motion(load_scene("glass-drum-3d", over))
    info = motion.backend_info()["precision"]
    assert info["mechanics"] == "float32" and info["positions"] == "float64"
    assert info["spacing_over_weight_overlap"] < 0.25
    assert info["position_spacing_m"][2] == np.spacing(np.float32(motion.dem.fold_length))
    assert info["slowest_moving_speed_m_s"][2] < 1e-10
    with pytest.raises(ValueError, match="not narrower"):
        _drum(1.3, jnp.float64, position_dtype=jnp.float32)

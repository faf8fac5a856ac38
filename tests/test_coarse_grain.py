"""Coarse-grained thermal DEM (``[dem] coarse_grain = s``, docs/models/coarse-graining.md):
s = 1 is the code path without the key; parcels keep the fine bed's conductivity, mass, heat
capacity and loss per unit mass; the mechanics scale as Bierwisch et al. 2009; what is not
supported is refused."""

import math

import jax.numpy as jnp
import numpy as np
import pytest

import drumheat as dh
from drumheat import assemble
from drumheat.analysis.validation import lattice_bar
from drumheat.scene import SceneError
from drumheat.thermal.contact import coarse_grained_alpha
from drumheat.thermal.effect import GasState

SMALL = {"groups.0.count": 2000, "run.duration": 0.02, "run.output_interval": 0.01,
         "dem.replay_after": None, "dem.record_interval": None, "dem.replay_cycle": None}


def drum(**more):
    """The glass drum (2000 beads of 8 mm), shortened, with ``more`` dotted overrides."""
    return dh.load_scene("glass-drum-3d", {**SMALL, **more})


def test_s1_is_the_code_path_without_the_key():
    base = drum()
    one = drum(**{"dem.coarse_grain": 1.0})
    assert one.coarse_grain == 1.0 and one.n_parcels == one.n_particles == 2000
    a, b = assemble.dem_setup(base), assemble.dem_setup(one)
    assert (a.k_n, a.t_crit, a.dt, a.dt_origin) == (b.k_n, b.t_crit, b.dt, b.dt_origin)
    assert np.array_equal(np.asarray(a.particles.mass), np.asarray(b.particles.mass))
    assert np.array_equal(assemble.diameters(base), assemble.diameters(one))
    ma, _ = assemble.thermal_model(base)
    mb, _ = assemble.thermal_model(one)
    for name in ("contact", "wall"):
        assert float(ma.effect(name).alpha) == float(mb.effect(name).alpha)
    assert np.array_equal(np.asarray(ma.particles.capacity), np.asarray(mb.particles.capacity))
    assert coarse_grained_alpha(57.0, 1.0) == 57.0


@pytest.mark.parametrize("lattice", ["sc", "fcc"])
@pytest.mark.parametrize("s", [2.0, 3.0])
def test_parcel_lattice_keeps_the_effective_conductivity(lattice, s):
    """A static lattice of parcels (diameter s d, alpha_pp / s) conducts as the fine lattice
    (drumheat.analysis.validation.lattice_bar, steady state by drumheat's own solver)."""
    fine = lattice_bar(lattice, 6, d=0.008, alpha_pp=57.0)
    coarse = lattice_bar(lattice, 6, d=s * 0.008, alpha_pp=coarse_grained_alpha(57.0, s))
    assert coarse["lambda_interior"] == pytest.approx(fine["lambda_interior"], rel=1e-9)
    assert coarse["lambda_ref"] == pytest.approx(fine["lambda_ref"], rel=1e-12)


def test_the_contact_effect_divides_alpha_by_s():
    m1, _ = assemble.thermal_model(drum())
    m2, _ = assemble.thermal_model(drum(**{"dem.coarse_grain": 2.0}))
    assert float(m2.effect("contact").alpha) == pytest.approx(float(m1.effect("contact").alpha) / 2)
    # the wall coefficient per unit area is kept
    assert float(m2.effect("wall").alpha) == float(m1.effect("wall").alpha)


def test_schluender_alpha_is_of_the_real_particles():
    more = {"heat.contact.model": "schluender", "heat.wall.model": "schluender",
            "heat.contact.alpha": None, "heat.wall.alpha": None}
    m1, _ = assemble.thermal_model(drum(**more))
    m2, _ = assemble.thermal_model(drum(**more, **{"dem.coarse_grain": 2.0}))
    assert float(m2.effect("contact").alpha) == pytest.approx(float(m1.effect("contact").alpha) / 2,
                                                            rel=1e-12)
    assert float(m2.effect("wall").alpha) == pytest.approx(float(m1.effect("wall").alpha),
                                                         rel=1e-12)


def test_mass_and_heat_capacity_are_conserved():
    fine = assemble.thermal_particles(drum(), assemble.scene_values(drum()))
    sc = drum(**{"dem.coarse_grain": 2.0})  # 2000 / 8 = 250 parcels exactly
    coarse = assemble.thermal_particles(sc, assemble.scene_values(sc))
    assert sc.n_parcels == 250 and coarse.diameter.shape == (250,)
    assert float(coarse.mass[0]) == pytest.approx(8 * float(fine.mass[0]), rel=1e-12)
    assert float(jnp.sum(coarse.capacity)) == pytest.approx(float(jnp.sum(fine.capacity)),
                                                            rel=1e-12)
    assert np.allclose(assemble.diameters(sc), 0.016)


def test_loss_per_unit_mass_is_kept():
    air = {"gas.material": "air", "gas.temperature": 293.0, "heat.loss.alphaA": 2.5e-4}
    for s in (1.0, 2.0, 3.0):
        sc = drum(**air, **{"dem.coarse_grain": s, "groups.0.count": 3000, "drum.depth": 0.078})
        model, _ = assemble.thermal_model(sc)
        per_mass = float(model.effect("loss").alphaA) / float(model.particles.mass[0])
        if s == 1.0:
            ref = per_mass
        assert per_mass == pytest.approx(ref, rel=1e-12)


def test_mechanics_scale_as_bierwisch():
    fine = assemble.dem_setup(drum(**{"dem.wall_stiffness": 2.0e5}))
    coarse = assemble.dem_setup(drum(**{"dem.wall_stiffness": 2.0e5, "dem.coarse_grain": 2.0}))
    assert coarse.k_n == pytest.approx(2 * fine.k_n)
    assert float(coarse.params.kn_pw.max()) == pytest.approx(2 * float(fine.params.kn_pw.max()))
    assert coarse.t_crit == pytest.approx(2 * fine.t_crit, rel=1e-12)  # sqrt(8 m / 2 k)
    assert coarse.dt == pytest.approx(2 * fine.dt, rel=1e-12)
    given = assemble.dem_setup(drum(**{"dem.dt": 1e-5, "dem.coarse_grain": 2.0}))
    assert given.dt == pytest.approx(2e-5)
    # the default stiffness E A_p / d_p of the parcel is also s times the particle's
    d1 = assemble.dem_setup(drum(**{"dem.stiffness": None}))
    d2 = assemble.dem_setup(drum(**{"dem.stiffness": None, "dem.coarse_grain": 2.0}))
    assert d2.k_n == pytest.approx(2 * d1.k_n, rel=1e-12)


def test_a_coarse_drum_runs_and_reports_parcels():
    sc = dh.load_scene("glass-drum-3d", {
        "groups.0.count": 400, "drum.depth": 0.052, "run.duration": 0.02,
        "run.output_interval": 0.01, "dem.replay_after": None, "dem.record_interval": None,
        "dem.replay_cycle": None, "dem.coarse_grain": 2.0})
    res = dh.run(sc, progress=False)
    assert res.summary["n_particles"] == 50 and res.summary["n_real_particles"] == 400
    assert res.summary["coarse_grain"] == 2.0
    assert res.summary["complete"] and res.summary["energy_balance_rel_error"] < 1e-10
    assert res.trajectory.T.shape == (3, 50)


@pytest.mark.parametrize("more, words", [
    ({"dem.coarse_grain": 0.5}, ">= 1"),
    ({"dem.coarse_grain": 2.0, "heat.friction.partition": "half"}, "[heat.friction]"),
    ({"dem.coarse_grain": 6.0, "groups.0.count": 100}, "no parcel"),
    ({"dem.coarse_grain": 3.0}, "periodic slice"),
])
def test_bad_input_is_refused(more, words):
    with pytest.raises(SceneError) as err:
        drum(**more)
    assert "coarse_grain" in str(err.value) or words in str(err.value)
    assert words in str(err.value)


def test_2d_and_other_motion_models_are_refused():
    with pytest.raises(SceneError, match="dim = 3"):
        dh.load_scene("weigler-glass-drum-9.55", {"dem.coarse_grain": 2.0})
    with pytest.raises(SceneError, match="motion model"):
        drum(**{"dem.coarse_grain": 2.0, "motion.model": "static"})
    assert math.isclose(drum(**{"dem.coarse_grain": 2.0}).coarse_grain, 2.0)

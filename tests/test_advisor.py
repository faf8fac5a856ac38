"""The effect advisor and `drumheat explain`."""

import pytest

from drumheat.analysis.advisor import explain
from drumheat.cli import main


def test_weigler_static_is_contact_dominated_and_lumped():
    adv = explain("weigler-static")
    terms = {t.name: t for t in adv.terms}
    assert terms["contact conduction"].relative == pytest.approx(1.0)
    assert terms["contact conduction"].included and terms["contact conduction"].verdict == "keep"
    assert terms["convection"].verdict == "covered by [heat.loss]"
    assert terms["heat loss (lumped)"].verdict.startswith("keep")  # acts over the whole run
    assert adv.biot < 0.1 and "lumped particles are fine" in adv.biot_verdict


def test_slag_droplet_needs_internal_conduction():
    adv = explain("staltner-slag-particle")
    terms = {t.name: t for t in adv.terms}
    assert adv.biot > 0.1 and "needed" in adv.biot_verdict
    assert terms["radiation"].included and terms["convection"].included
    # radiation of a 1350 degC droplet is of the order of its convection (staltner chapter 8)
    assert 0.3 < terms["radiation"].heat_flow / terms["convection"].heat_flow < 3


def test_wall_heated_glass_bed_flags_missing_effects():
    adv = explain("weigler-glass-wall")
    terms = {t.name: t for t in adv.terms}
    assert terms["contact conduction"].verdict == "keep"  # carries the wall heat into the bed
    assert not terms["radiation"].included


def test_cli_explain(capsys):
    assert main(["explain", "weigler-static"]) == 0
    out = capsys.readouterr().out
    assert "contact conduction" in out and "Biot number" in out
    assert main(["explain", "no-such-scene"]) == 2


def test_wall_layer_of_a_plain_drum_matches_the_segment_geometry():
    """DEM drum scenes (no contact network at t = 0) get the wall layer of their bed segment."""
    import math

    from drumheat.analysis.advisor import _wall_layer_fraction
    from drumheat.scene import load_scene

    scene = load_scene("weigler-glass-drum-9.55")
    frac, note = _wall_layer_fraction(scene, scene.groups[0].diameter)
    # half-filled 2D drum (f = 1/2): eps = pi/2, wetted arc pi R, arc/d particles in the layer
    R, d = 0.5 * scene.drum.diameter, scene.groups[0].diameter
    n_half = 0.8 * math.pi * R * R / 2 / (math.pi * d * d / 4)  # particles that half-fill it
    half = load_scene("weigler-glass-drum-9.55", {"groups.0.count": int(round(n_half))})
    f_half, _ = _wall_layer_fraction(half, d)
    assert f_half * half.n_particles == pytest.approx(math.pi * R / d, rel=2e-3)
    assert 0 < frac < 1 and "segment" in note
    adv = explain(scene)  # used to fail: a DEM bed has no contact network at t = 0
    terms = {t.name: t for t in adv.terms}
    assert terms["wall contact"].conductance > 0 and terms["wall contact"].dT == pytest.approx(50.0)


def test_moving_bed_heat_comes_from_the_tubes_not_the_gas():
    adv = explain("kraychev-tube-bundle")
    terms = {t.name: t for t in adv.terms}
    wall = terms["wall contact"]
    assert wall.dT == pytest.approx(291.15 - 258.15) and wall.verdict == "keep"
    assert "tubes" in wall.note
    assert terms["convection"].conductance == 0  # no secondary gas through the bed
    assert terms["convection"].verdict.startswith("negligible")


@pytest.mark.parametrize("name", ["herz-sectional-drum", "weigler-mixed"])
def test_every_dem_scene_can_be_explained(name):
    adv = explain(name)
    assert adv.terms[0].name == "contact conduction" and adv.terms[0].conductance > 0


@pytest.mark.parametrize("model, can", [("static", True), ("dem", False)])
def test_internal_conduction_is_recommended_only_where_the_motion_model_has_it(model, can):
    from drumheat.scene import load_scene

    # alpha_wp = 1e4 W/(m2 K) on 8 mm glass: Bi = (alpha/4) r / lambda >> 0.1
    scene = load_scene("weigler-glass-drum-9.55", {"heat.wall.alpha": 1.0e4,
                                                   "motion.model": model})
    adv = explain(scene)
    assert adv.biot > 0.1
    if can:
        assert "add [heat.internal]" in adv.biot_verdict
    else:  # the DEM refuses [heat.internal]: the advice says so instead of recommending it
        assert "cannot resolve" in adv.biot_verdict and "add [heat.internal]" not in adv.biot_verdict


def test_friction_heat_is_the_drive_power_of_a_half_filled_drum():
    """Half-filled 2D drum: the bed's centre of mass sits at 4R/(3 pi) from the axis (centroid
    of a half disc), offset sideways by sin(theta) at the angle of repose; in steady rotation
    the drive's power omega M g x_c is all dissipated (docs/models/friction-heat.md)."""
    import math

    from drumheat.materials import material
    from drumheat.scene import load_scene

    base = load_scene("weigler-glass-drum-9.55")
    R, d = 0.5 * base.drum.diameter, base.groups[0].diameter
    n_half = int(round(0.8 * math.pi * R * R / 2 / (math.pi * d * d / 4)))
    scene = load_scene("weigler-glass-drum-9.55",
                       {"groups.0.count": n_half, "packing.surface_angle": 35.0})
    terms = {t.name: t for t in explain(scene).terms}
    fric = terms["friction heat"]
    g0 = scene.groups[0]
    rho = g0.density or material(g0.material).density
    mass = n_half * rho * math.pi * d**3 / 6
    omega = 2 * math.pi * scene.drum.rpm / 60
    x_c = 4 * R / (3 * math.pi) * math.sin(math.radians(35.0))
    # the fill is n_half's rounding away from exactly one half
    assert fric.heat_flow * n_half == pytest.approx(omega * mass * 9.81 * x_c, rel=2e-3)
    assert not fric.included and fric.verdict.startswith("negligible")
    # still drum, no term; a drum turning 20x faster over a long run without wall heating:
    # the friction heat is what warms the bed
    assert "friction heat" not in {t.name for t in explain(
        load_scene("weigler-glass-drum-9.55", {"drum.rpm": 0.0})).terms}
    mill = load_scene("weigler-glass-drum-9.55", {"drum.rpm": 191.0,
                                                  "drum.wall_temperature": 293.15})
    fric = {t.name: t for t in explain(mill).terms}["friction heat"]
    assert fric.verdict.startswith("should be added")

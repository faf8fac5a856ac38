"""The effect advisor and `drumheat explain`."""

import pytest

from drumheat.advisor import explain
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

"""scripts/weigler_mixed_candidates.py: every candidate is expressible by scene keys, changes
what it says it changes, and the filling-order row really puts the other group at the bottom."""

import importlib.util
from pathlib import Path

import numpy as np

from drumheat import assemble, load_scene

SCRIPT = Path(__file__).resolve().parents[1] / "scripts" / "weigler_mixed_candidates.py"


def script():
    spec = importlib.util.spec_from_file_location("weigler_mixed_candidates", SCRIPT)
    mod = importlib.util.module_from_spec(spec)
    spec.loader.exec_module(mod)
    return mod


def test_every_candidate_loads_and_changes_the_scene():
    c = script()
    base = c.load([], c.DURATION)
    rows = c.candidates()
    assert len({label for label, _ in rows}) == len(rows)
    for label, ov in rows:
        scene = c.load(ov, c.DURATION)  # accepted by load_scene, no patching
        if label != "base, seed 1":
            assert scene != base, label
    by = dict(rows)
    assert c.load(by["stiffness x 10"], 600).dem.stiffness == 10 * base.dem.stiffness
    assert c.load(by["coupled DEM for the whole run"], 600).dem.replay_after is None
    assert c.load(by["overlap-only conduction"], 600).heat.contact.gap_tolerance == 0.0


def test_warm_first_lays_the_warm_spheres_at_the_bottom_of_the_same_packing():
    c = script()
    base = c.load([], c.DURATION)
    swapped = c.load(dict(c.candidates())["filling: warm first"], c.DURATION)
    p0, p1 = assemble.initial_packing(base), assemble.initial_packing(swapped)
    np.testing.assert_array_equal(p0.position, p1.position)  # same positions ...
    T0 = np.array([g.temperature for g in base.groups])[p0.group]
    T1 = np.array([g.temperature for g in swapped.groups])[p1.group]
    np.testing.assert_array_equal(np.sort(T0), np.sort(T1))  # ... same temperatures ...
    y = p0.position[:, 1]
    # ... but the warm spheres at the bottom: layers pour the first group first
    assert y[T0 < 310].mean() < y[T0 > 310].mean()
    assert y[T1 > 310].mean() < y[T1 < 310].mean()

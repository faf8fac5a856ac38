"""Heat uptake of a turning bed does not depend on the softened stiffness (issue 16).

The glass drum of weigler-glass-drum-9.55 (370 spheres of 8 mm, D = 250 mm, 9.55 rpm, wall at
343 K), coupled DEM for 10 s at k = 1e5 and 1e6 N/m. The bed's heat uptake alpha A (W/K) over
the second half (after the start-up from rest) changes by less than 3 % with the default
conduction gap tolerance (1 % of d) and by much more with tolerance 0 (the control: contacts
conduct only while they overlap, and a softer contact chatters shut for longer).

Slow (about 8 minutes on 2 cores): ``pytest -m slow tests/test_stiffness_independence.py``.
"""

import pytest

import drumheat as dh


def heat_uptake(k: float, gap: float) -> float:
    scene = dh.load_scene("weigler-glass-drum-9.55", {
        "run.duration": 10.0, "run.output_interval": 1.0, "dem.stiffness": k,
        "dem.replay_after": None, "dem.record_interval": None, "dem.replay_cycle": None,
        "heat.contact.gap_tolerance": gap, "heat.wall.gap_tolerance": gap})
    ts = dh.run(scene, progress=False).timeseries
    h = len(ts) // 2
    dQ = ts["Q_wall"].iloc[-1] - ts["Q_wall"].iloc[h]
    dt = ts["t"].iloc[-1] - ts["t"].iloc[h]
    return dQ / dt / (scene.drum.wall_temperature - ts["T_mean"].iloc[h:].mean())


@pytest.mark.slow
def test_heat_uptake_does_not_follow_the_stiffness():
    with_gap = heat_uptake(1e6, 0.01) / heat_uptake(1e5, 0.01) - 1
    overlap_only = heat_uptake(1e6, 0.0) / heat_uptake(1e5, 0.0) - 1
    assert abs(with_gap) < 0.03, with_gap
    assert abs(overlap_only) > 3 * abs(with_gap) and abs(overlap_only) > 0.10, overlap_only

"""The progress bar: simulated time shown, percentage and ETA following the run's cost."""

import io
import sys

import numpy as np

import drumheat as dh
from drumheat.motion import make_motion
from drumheat.runner.loop import _work, estimate
from drumheat.runner.progress import SimProgress


def test_bar_advances_by_work_and_shows_simulated_time(monkeypatch):
    err = io.StringIO()
    monkeypatch.setattr(sys, "stderr", err)
    work = lambda t: t**2  # noqa: E731  (cost grows with simulated time)
    with SimProgress(10.0, True, delay=0.0, work=work) as bar:
        assert bar.bar.total == 100.0
        bar.update_to(5.0)
        assert bar.bar.n == 25.0
        bar.update_to(10.0)
        assert bar.bar.n == 100.0
    assert "t = 10 / 10 s" in err.getvalue()


def test_replay_chunks_cost_less_than_dem_chunks():
    """weigler-mixed runs the DEM for dem.replay_after seconds and replays after that: with
    the estimate's cost model the replayed seconds weigh far less than the DEM's, so the ETA
    during the DEM is that of the whole run, not of a DEM run throughout."""
    scene = dh.load_scene("weigler-mixed", {"run.duration": 60.0, "run.output_interval": 2.5,
                                            "dem.replay_after": 10.0})
    motion = make_motion(scene)
    uniform = _work(motion, motion.times)  # before any estimate: mechanical steps
    assert uniform(10.0) > 0.99 * uniform(60.0)
    cost = estimate(motion)
    w = _work(motion, motion.times)
    per_second_dem = w(10.0) / 10.0
    per_second_replay = (w(60.0) - w(10.0)) / 50.0
    assert per_second_replay < 0.2 * per_second_dem
    # the whole run's work is the estimate's wall time
    np.testing.assert_allclose(w(60.0), cost["seconds"], rtol=0.05)


def test_bar_says_when_the_run_switches_to_the_replay(monkeypatch):
    """The switch to the cyclic replay (dem.replay_after) can take minutes at large N (the
    restart assignment): the bar names it while it runs, and only then."""
    scene = dh.load_scene("weigler-mixed", {"run.duration": 60.0, "run.output_interval": 2.5,
                                            "dem.replay_after": 10.0})
    motion = make_motion(scene)
    notes = {float(t): motion.between_note(float(t)) for t in motion.times[1:]}
    assert [t for t, note in notes.items() if note] == [10.0]
    assert "replay" in notes[10.0] and f"{motion.n} particles" in notes[10.0]
    err = io.StringIO()
    monkeypatch.setattr(sys, "stderr", err)
    with SimProgress(60.0, True, delay=0.0) as bar:
        bar.update_to(10.0)
        bar.note(notes[10.0])
        assert bar.bar.postfix == f"t = 10 / 60 s, {notes[10.0]}"
        bar.update_to(12.5)
        assert bar.bar.postfix == "t = 12.5 / 60 s"
    assert notes[10.0] in err.getvalue()

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

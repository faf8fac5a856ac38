"""[dem] contact_backend: which contact kernel a scene's DEM runs on, and the fallback."""

import sys
import warnings
from pathlib import Path

import pytest

import drumheat as dh
from drumheat.mechanics import cpu_kernel
from drumheat.mechanics.backend import choose_contact_backend
from drumheat.mechanics import DEMAccuracyWarning
from drumheat.scene import SceneError

sys.path.insert(0, str(Path(__file__).parent))
from test_coupled import dem_scene  # noqa: E402


@pytest.fixture
def no_compiler(monkeypatch):
    """The C++ kernel cannot be built here (as on a machine without a C++ compiler)."""
    monkeypatch.setattr(cpu_kernel, "_STATE", (False, "no C++ compiler found (simulated)"))


def choose(requested, **kw):
    scene = dem_scene()
    from drumheat.motion import make_motion

    m = make_motion(scene.replace({"dem.contact_backend": "jax"}))
    return choose_contact_backend(requested, dim=2, params=m.params, dtype=m.dtype, **kw)


def test_jax_is_always_jax_and_ensembles_run_on_jax():
    assert choose("jax").backend == "jax" and choose("jax").reason is None
    batched = choose("auto", batched=True)
    assert batched.backend == "jax" and "ensembles" in batched.reason


def test_auto_takes_the_cpu_kernel_where_it_can(no_compiler):
    with warnings.catch_warnings():
        warnings.simplefilter("error")  # auto falls back silently ...
        # (dem_scene's step is above the dashpot limit on purpose: test_coupled.dem_scene)
        warnings.filterwarnings("ignore", category=DEMAccuracyWarning)
        c = choose("auto")
    assert c.backend == "jax" and "simulated" in c.reason  # ... and says why


def test_cpu_falls_back_with_one_line_and_the_summary_says_so(no_compiler):
    with pytest.warns(RuntimeWarning, match="cannot be used") as record:
        res = dh.run(dem_scene(**{"dem.contact_backend": "cpu", "run.duration": 0.05}),
                     progress=False)
    assert len([w for w in record if "contact_backend" in str(w.message)]) == 1
    assert res.summary["contact_backend"] == "jax"
    assert "simulated" in res.summary["contact_backend_note"]


@pytest.mark.skipif(not cpu_kernel.available()[0], reason="no C++ compiler here")
def test_auto_runs_the_cpu_kernel_and_reports_it():
    res = dh.run(dem_scene(**{"run.duration": 0.05}), progress=False)
    assert res.summary["contact_backend"] == "cpu"
    assert "contact_backend_note" not in res.summary


def test_unknown_backend_is_refused():
    with pytest.raises(SceneError, match="contact_backend"):
        dem_scene(**{"dem.contact_backend": "gpu"})

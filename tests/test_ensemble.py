"""Ensembles (drumheat.run_ensemble) and sharding over several devices (drumheat.runner.sharding).

The vmapped ensemble must give what ``drumheat.run`` gives for every variant; sharded runs
(variant axis or particle axis over 4 simulated CPU devices) what one device gives. The
multi-device checks run in a subprocess because the device count must be set (XLA_FLAGS)
before JAX is imported.
"""

import json
import os
import subprocess
import sys
import textwrap
from pathlib import Path

import numpy as np
import pytest

import drumheat as dh
from drumheat.runner.ensemble import EnsembleWarning, expand_overrides
from drumheat.scene import SceneError, load_scene, scene_from_dict

ROOT = Path(__file__).resolve().parents[1]


def static_scene():
    return load_scene("weigler-static", {"run.duration": 120.0})


def dem_scene(**over):
    """30 aluminium spheres (soft contacts) in the 50 mm drum at 12 rpm; 10 DEM steps
    (2 outputs of 5 steps of 25 us) with a large contact coefficient so that heat moves."""
    raw = load_scene("weigler-static").to_dict()
    raw["name"] = "ensemble-test"
    raw["groups"][0]["count"] = raw["groups"][1]["count"] = 15
    raw["run"].update(duration=2.5e-4, output_interval=1.25e-4, solver="explicit")
    raw["drum"]["rpm"] = 12.0
    raw["heat"]["contact"]["alpha"] = 1.0e5
    raw["motion"] = {"model": "dem"}
    raw["dem"] = {"stiffness": 2.0e4, "thermal_substeps": 1}
    scene = scene_from_dict(raw)
    return scene.with_overrides(over) if over else scene


def assert_same_results(ens, scenes, rtol=1e-10):
    for k, scene in enumerate(scenes):
        ref = dh.run(scene, progress=False)
        got = ens[k]
        assert list(got.timeseries.columns) == list(ref.timeseries.columns)
        np.testing.assert_allclose(got.T, ref.T, rtol=rtol, atol=0)
        np.testing.assert_allclose(got.trajectory.position, ref.trajectory.position, rtol=0,
                                   atol=1e-15)
        for col in ref.timeseries.columns:
            np.testing.assert_allclose(got.timeseries[col], ref.timeseries[col], rtol=rtol,
                                       atol=1e-9, err_msg=col)
        assert got.summary["energy_balance_rel_error"] < 1e-10


def test_expand_overrides_grid_list_and_copies():
    v = expand_overrides({"heat.contact.alpha": [80.0, 120.0], "run.seed": [1, 2, 3],
                          "run.duration": 60.0})
    assert len(v) == 6
    assert v[0] == {"run.duration": 60.0, "heat.contact.alpha": 80.0, "run.seed": 1}
    assert v[5] == {"run.duration": 60.0, "heat.contact.alpha": 120.0, "run.seed": 3}
    assert expand_overrides([{"run.seed": 4}]) == [{"run.seed": 4}]
    assert expand_overrides(2) == [{}, {}]
    with pytest.raises(SceneError):
        expand_overrides([])
    with pytest.raises(SceneError):
        expand_overrides(["run.seed=3"])


def test_static_ensemble_equals_individual_runs():
    base = static_scene()
    variants = [{"heat.contact.alpha": 80.0},
                {"heat.contact.alpha": 130.0, "run.seed": 2, "gas.temperature": 300.0},
                {"heat.loss.alphaA": 5e-4, "groups.0.temperature": 290.0}]
    ens = dh.run_ensemble(base, variants, progress=False)
    assert ens.vmapped and len(ens) == 3 and ens.wall_time_s > 0 and ens.throughput > 0
    scenes = [base.with_overrides(v) for v in variants]
    assert_same_results(ens, scenes)
    # different seeds gave different packings, and the parameters mattered
    assert not np.allclose(ens[0].trajectory.position, ens[1].trajectory.position)
    assert ens[0].summary["T_mean:cold"] != ens[1].summary["T_mean:cold"]
    table = ens.timeseries()
    assert set(table["variant"]) == {0, 1, 2} and "heat.contact.alpha" in table


def test_sweep_by_name_speedup_report_and_files(tmp_path):
    ens = dh.run_ensemble("weigler-static", {"heat.contact.alpha": [90.0, 120.0],
                                             "run.duration": 60.0}, progress=False)
    assert [r.scene.heat.contact.alpha for r in ens] == [90.0, 120.0]
    assert ens.compare_sequential() > 0
    assert "speed-up" in ens.summary()
    out = ens.save(tmp_path / "sweep")
    assert (out / "variant_001" / "timeseries.csv").is_file()
    assert (out / "ensemble_timeseries.csv").is_file()


def test_bad_overrides_are_refused_naming_the_key():
    base = static_scene()
    with pytest.raises(SceneError, match="heat.contact.alpha"):
        dh.run_ensemble(base, [{"heat.contact.alpha": -1.0}], progress=False)
    with pytest.raises(SceneError, match="no_such"):
        dh.run_ensemble(base, [{"heat.no_such": 1.0}], progress=False)
    # variants must share what the one program is built from
    with pytest.raises(SceneError, match="groups.0.count.*particle count"):
        dh.run_ensemble(base, {"groups.0.count": [35, 36]}, progress=False)
    with pytest.raises(SceneError, match="run.duration.*output times"):
        dh.run_ensemble(base, {"run.duration": [60.0, 90.0]}, progress=False)
    with pytest.raises(SceneError, match="heat.wall.*effects"):
        dh.run_ensemble(base, [{}, {"heat.wall.alpha": 100.0, "drum.wall_temperature": 330.0}],
                        progress=False)
    with pytest.raises(SceneError, match="run.solver.*solver"):
        dh.run_ensemble(base, {"run.solver": ["adaptive", "implicit"]}, progress=False)


def test_dem_ensemble_equals_individual_runs():
    # chaotic dynamics: a 1e-17 m perturbation of the deposited packing grows to ~1e-6 m in
    # 100 steps, so agreement to round-off can only be checked over a few steps (10 here);
    # the vmapped and single programs then agree bit for bit or nearly
    base = dem_scene()
    variants = [{"run.seed": 1}, {"run.seed": 2, "heat.contact.alpha": 2.0e5,
                                  "groups.1.temperature": 330.0}]
    ens = dh.run_ensemble(base, variants, progress=False)
    assert ens.vmapped
    assert_same_results(ens, [base.with_overrides(v) for v in variants], rtol=1e-12)
    assert not np.allclose(ens[0].trajectory.position[0], ens[1].trajectory.position[0])
    assert np.ptp(ens[1].T[-1] - ens[1].T[0]) > 1e-3  # heat moved


def test_dem_mechanics_that_differ_are_refused():
    with pytest.raises(SceneError, match="dem.friction.*contact parameters"):
        dh.run_ensemble(dem_scene(), {"dem.friction": [0.5, 0.9]}, progress=False)


def test_models_without_vmapping_run_one_by_one_with_a_warning():
    base = load_scene("staltner-slag-particle", {"heat.internal.shells": 20,
                                                 "granulator.steps_per_phase": 40})
    variants = [{"groups.0.diameter": 0.001}, {"groups.0.diameter": 0.002}]
    with pytest.warns(EnsembleWarning, match="one after the other"):
        ens = dh.run_ensemble(base, variants, progress=False)
    assert not ens.vmapped
    for r, v in zip(ens, variants):
        ref = dh.run(base.with_overrides(v), progress=False)
        np.testing.assert_array_equal(r.T, ref.T)


@pytest.mark.parametrize("model", ["random", "replay"])
def test_random_and_replay_ensembles_equal_individual_runs(model, tmp_path):
    """Every pure motion model runs its variants as one vmapped program (the generic loop
    over vmap(advance)), with the results of single runs."""
    if model == "random":
        base = static_scene().with_overrides({"motion.model": "random", "motion.t_R": 40.0,
                                              "run.duration": 100.0})
        variants = [{"heat.contact.alpha": 80.0}, {"heat.contact.alpha": 120.0, "run.seed": 5}]
    else:  # a replay of a short recording, variants in the thermal parameters
        rec = dem_scene(**{"dem.record_interval": 1.25e-4 / 5})
        dh.run(rec, out=tmp_path / "rec", progress=False)
        raw = rec.to_dict()
        raw["motion"] = {"model": "replay"}
        raw["replay"] = {"file": str(tmp_path / "rec" / "contacts.npz")}
        raw["run"]["duration"] = 10 * raw["run"]["output_interval"]
        del raw["dem"]
        base = scene_from_dict(raw)
        variants = [{"heat.contact.alpha": 5.0e4}, {"heat.contact.alpha": 2.0e5,
                                                    "groups.1.temperature": 320.0}]
    ens = dh.run_ensemble(base, variants, progress=False)
    assert ens.vmapped
    assert_same_results(ens, [base.with_overrides(v) for v in variants])
    assert not np.allclose(ens[0].T[-1], ens[1].T[-1])


def test_fluidized_ensemble_equals_individual_runs():
    base = load_scene("fluidized-bed-coffee", {"run.duration": 20.0, "groups.0.count": 40,
                                               "heat.internal.shells": 8})
    variants = [{"gas.temperature": 293.15}, {"gas.temperature": 303.15, "run.seed": 4}]
    ens = dh.run_ensemble(base, variants, progress=False)
    assert ens.vmapped
    assert_same_results(ens, [base.with_overrides(v) for v in variants])


SHARDED_SCRIPT = textwrap.dedent('''
    import json, sys
    import numpy as np
    import jax
    import drumheat as dh
    from drumheat.motion.static import StaticBed
    from drumheat.runner.sharding import make_mesh, shard_particles
    sys.path.insert(0, {tests!r})
    from test_ensemble import dem_scene, static_scene

    out = {{"n_devices": len(jax.devices())}}
    rel = lambda a, b: float(np.max(np.abs(a - b) / np.abs(b)))
    dpos = lambda a, b: float(np.max(np.abs(a.trajectory.position - b.trajectory.position)))

    # ensemble axis: 3 variants over 4 devices (padded to 4)
    ov = {{"heat.contact.alpha": [80.0, 105.0, 130.0]}}
    e1 = dh.run_ensemble(static_scene(), ov, progress=False)
    e4 = dh.run_ensemble(static_scene(), ov, progress=False, devices="all")
    out["static_ensemble_T"] = max(rel(a.T, b.T) for a, b in zip(e4, e1))
    out["static_ensemble_devices"] = e4.n_devices

    # particle axis: 72 particles, 18 per device
    sc = static_scene().with_overrides({{"groups.0.count": 36, "groups.1.count": 36}})
    r1 = dh.run(sc, progress=False)
    r4 = dh.run(sc, progress=False, devices=4)
    out["static_particles_T"] = rel(r4.T, r1.T)
    model, T0 = StaticBed(sc).model()
    _, T0s = shard_particles((model, T0), make_mesh(), sc.n_particles)
    out["static_particles_spec"] = [str(s) for s in T0s.sharding.spec]

    # DEM ensemble over the devices
    ovd = [{{"run.seed": 1}}, {{"run.seed": 2, "heat.contact.alpha": 2.0e5}}, {{"run.seed": 3}}]
    d1 = dh.run_ensemble(dem_scene(), ovd, progress=False)
    d4 = dh.run_ensemble(dem_scene(), ovd, progress=False, devices="all")
    out["dem_ensemble_T"] = max(rel(a.T, b.T) for a, b in zip(d4, d1))
    out["dem_ensemble_pos"] = max(dpos(a, b) for a, b in zip(d4, d1))

    # motion models without particle sharding refuse devices=
    rnd = static_scene().with_overrides({{"motion.model": "random", "motion.t_R": 40.0}})
    try:
        dh.run(rnd, progress=False, devices="all")
        out["random_refused"] = False
    except ValueError as err:
        out["random_refused"] = "does not support" in str(err)
    print("RESULT " + json.dumps(out))
''')


def run_on_four_devices(script: str, tmp_path, timeout=540) -> dict:
    path = tmp_path / "sharded.py"
    path.write_text(script)
    env = dict(os.environ, XLA_FLAGS="--xla_force_host_platform_device_count=4",
               PYTHONPATH=str(ROOT), JAX_PLATFORMS="cpu")
    proc = subprocess.run([sys.executable, str(path)], cwd=ROOT, env=env, capture_output=True,
                          text=True, timeout=timeout)
    assert proc.returncode == 0, proc.stdout[-3000:] + proc.stderr[-3000:]
    line = [s for s in proc.stdout.splitlines() if s.startswith("RESULT ")][-1]
    return json.loads(line[len("RESULT "):])


def test_sharded_runs_equal_one_device(tmp_path):
    out = run_on_four_devices(SHARDED_SCRIPT.format(tests=str(ROOT / "tests")), tmp_path)
    assert out["n_devices"] == 4
    assert out["static_ensemble_devices"] == 4
    assert out["static_ensemble_T"] < 1e-12
    assert out["static_particles_T"] < 1e-12
    assert out["static_particles_spec"] == ["d"]  # temperatures split by particle
    assert out["dem_ensemble_T"] < 1e-12
    assert out["dem_ensemble_pos"] < 1e-15
    assert out["random_refused"]


DEM_PARTICLES_SCRIPT = textwrap.dedent('''
    import json, sys
    import numpy as np
    import jax
    import drumheat as dh
    from drumheat.assemble import initial_packing
    sys.path.insert(0, {tests!r})
    from test_ensemble import dem_scene

    # a packing pressed together by 0.1 % (every touching pair overlaps by ~4 um): with the
    # deposited packing as it is, touching pairs sit exactly at zero overlap and round-off
    # decides whether they conduct heat in the first step
    sc = dem_scene(**{{"groups.0.count": 16, "groups.1.count": 16}})
    pk = initial_packing(sc)
    np.savez({packing!r}, position=pk.position * 0.999, diameter=pk.diameter, group=pk.group)
    sc = sc.with_overrides({{"packing.method": "file", "packing.file": {packing!r}}})
    r1 = dh.run(sc, progress=False)
    r4 = dh.run(sc, progress=False, devices=4)
    out = {{"n_devices": len(jax.devices()),
           "T": float(np.max(np.abs(r4.T - r1.T) / r1.T)),
           "pos": float(np.max(np.abs(r4.trajectory.position - r1.trajectory.position))),
           "dT": float(np.ptp(r1.T[-1] - r1.T[0]))}}
    print("RESULT " + json.dumps(out))
''')


@pytest.mark.slow
def test_particle_sharded_dem_equals_one_device(tmp_path):
    script = DEM_PARTICLES_SCRIPT.format(tests=str(ROOT / "tests"),
                                         packing=str(tmp_path / "packing.npz"))
    out = run_on_four_devices(script, tmp_path)
    assert out["n_devices"] == 4
    assert out["dT"] > 1e-3
    assert out["T"] < 1e-12
    assert out["pos"] < 1e-15

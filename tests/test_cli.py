"""The drumheat command: listing, running, overrides, bad input (exit code 2, key named)."""

import json
import subprocess
import sys

import pytest

from drumheat.cli import main


def test_scenes_lists_every_builtin(capsys):
    assert main(["scenes"]) == 0
    out = capsys.readouterr().out.splitlines()
    names = [line.split()[0] for line in out]
    assert "weigler-static" in names and "weigler-glass-wall" in names
    assert all(len(line.split(None, 1)) == 2 for line in out)  # name and description


def test_run_writes_results_with_overrides(tmp_path, capsys):
    out = tmp_path / "res"
    code = main(["run", "weigler-heating", "--out", str(out), "--quiet",
                 "--set", "run.duration=120", "--set", "groups.0.temperature=300"])
    assert code == 0
    summary = json.loads((out / "summary.json").read_text())
    assert summary["duration_s"] == 120.0
    assert summary["scene"] == "weigler-heating"
    assert "results in" in capsys.readouterr().out


BAD_INPUT = [
    (["--set", "groups.0.diameter=-1"], "groups.0.diameter"),
    (["--set", "groups.0.count=0"], "groups.0.count"),
    (["--set", "groups.0.temperature=0"], "groups.0.temperature"),
    (["--set", "groups.0.material=gold"], "groups.0.material"),
    (["--set", "heat.magic.alpha=1"], "heat.magic"),
    (["--set", "heat.loss.model=magic"], "heat.loss.model"),
    (["--set", "run.duration=soon"], "run.duration"),
    (["--set", "run.speed=2"], "run.speed"),
    (["--set", "groups.5.temperature=300"], "groups.5"),
    (["--set", "nonsense"], "nonsense"),
]


@pytest.mark.parametrize("extra,key", BAD_INPUT)
def test_bad_input_exits_2_and_names_the_key(tmp_path, capsys, extra, key):
    out = tmp_path / "res"
    code = main(["run", "weigler-heating", "--out", str(out), "--quiet"] + extra)
    assert code == 2
    err = capsys.readouterr().err
    assert key in err
    assert not out.exists()
    assert list(tmp_path.iterdir()) == []  # nothing half-written


def test_missing_key_and_bad_file(tmp_path, capsys):
    scene = tmp_path / "s.toml"
    scene.write_text('name = "x"\n[run]\nduration = 10.0\noutput_interval = 1.0\n')
    assert main(["run", str(scene), "--out", str(tmp_path / "o")]) == 2
    assert "'drum'" in capsys.readouterr().err
    scene.write_text("this is = = not toml")
    assert main(["run", str(scene)]) == 2
    assert "TOML" in capsys.readouterr().err
    assert main(["run", "no-such-scene"]) == 2
    assert "built-in scenes" in capsys.readouterr().err


def test_console_script_exit_code():
    proc = subprocess.run([sys.executable, "-m", "drumheat.cli", "run", "weigler-static",
                           "--set", "groups.0.diameter=0"], capture_output=True, text=True)
    assert proc.returncode == 2
    assert "groups.0.diameter" in proc.stderr


def test_version(capsys):
    import drumheat

    with pytest.raises(SystemExit) as exit_:
        main(["--version"])
    assert exit_.value.code == 0
    assert capsys.readouterr().out.strip() == f"drumheat {drumheat.__version__}"


def test_figures_in_vector_formats(tmp_path, capsys):
    out = tmp_path / "res"
    assert main(["run", "weigler-static", "--out", str(out), "--quiet", "--set",
                 "run.duration=60", "--figure-format", "pdf", "--figure-format", "svg",
                 "--dpi", "200"]) == 0
    for name in ("mean_temperatures", "snapshot_final"):
        assert (out / f"{name}.pdf").is_file() and (out / f"{name}.svg").is_file()
        assert not (out / f"{name}.png").exists()


def test_new_scene_from_a_builtin(tmp_path, capsys):
    """`drumheat new` copies the template with its comments, writes each change into its
    table, and the file runs as a scene."""
    from drumheat.scene import load_scene

    path = tmp_path / "my-drum.toml"
    assert main(["new", str(path), "--set", "groups.0.count=1000", "--set", "drum.rpm=5",
                 "--set", "drum.depth=0.026", "--set", "run.duration=1"]) == 0
    assert "drumheat estimate" in capsys.readouterr().out
    text = path.read_text()
    template = load_scene("glass-drum-3d")
    assert "# The LIGGGHTS benchmark drum" in text  # the template's comments are kept
    assert "rpm = 5  # changed by drumheat new" in text
    scene = load_scene(path)
    assert scene.name == "my-drum" and scene.n_particles == 1000 and scene.drum.rpm == 5
    assert scene.heat == template.heat and scene.dem == template.dem
    # a table switched off, a key added
    other = tmp_path / "quiet.toml"
    assert main(["new", str(other), "--from", "weigler-static", "--set", "heat.loss=none",
                 "--set", "run.seed=7"]) == 0
    s = load_scene(other)
    assert s.heat.loss is None and s.run.seed == 7
    assert load_scene("weigler-static").heat.loss is not None


def test_new_scene_refuses_bad_input_and_keeps_files(tmp_path, capsys):
    path = tmp_path / "mine.toml"
    assert main(["new", str(path), "--set", "dem.stifness=1e5"]) == 2
    assert "mean 'stiffness'" in capsys.readouterr().err
    assert list(tmp_path.iterdir()) == []  # nothing half-written
    path.write_text("# mine\n")
    assert main(["new", str(path)]) == 2
    assert "exists" in capsys.readouterr().err and path.read_text() == "# mine\n"
    assert main(["new", str(path), "--force"]) == 0
    assert path.read_text() != "# mine\n"


def test_estimate_prints_the_cost_before_a_run(capsys):
    assert main(["estimate", "weigler-mixed"]) == 0
    out = capsys.readouterr().out
    assert "mechanical steps" in out and "estimated wall time" in out

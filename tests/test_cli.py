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

"""A run never deletes a folder it did not write (reliability issue, finding 1).

``--out .`` once deleted every file in the current folder; ``--out mydata`` replaced a folder of
the user's own files; a scene named ``../../x`` wrote outside ``results/``. Each case is refused
with exit code 2, before the run and with nothing touched.
"""

import json
import os

import pytest

from drumheat.cli import main
from drumheat.results.files import MANIFEST, ResultFolderError, check_out_dir, write_results
from drumheat.scene import SceneError, load_scene

QUICK = ["--quiet", "--set", "run.duration=60", "--set", "run.output_interval=30"]


@pytest.fixture(scope="module")
def result():
    import drumheat as dh

    return dh.run(load_scene("weigler-heating", {"run.duration": 60.0,
                                                 "run.output_interval": 30.0}), progress=False)


def _user_folder(path):
    path.mkdir()
    (path / "thesis.docx").write_text("years of work")
    (path / "data").mkdir()
    (path / "data" / "measured.csv").write_text("t,T\n0,300\n")
    return sorted(p.name for p in path.rglob("*"))


def test_out_dot_is_refused_and_the_folder_kept(tmp_path, monkeypatch, capsys):
    before = _user_folder(tmp_path / "work")
    monkeypatch.chdir(tmp_path / "work")
    assert main(["run", "weigler-heating", "--out", "."] + QUICK) == 2
    assert "current folder" in capsys.readouterr().err
    assert sorted(p.name for p in (tmp_path / "work").rglob("*")) == before


def test_a_folder_of_user_files_is_refused(tmp_path, capsys):
    before = _user_folder(tmp_path / "mydata")
    assert main(["run", "weigler-heating", "--out", str(tmp_path / "mydata")] + QUICK) == 2
    err = " ".join(capsys.readouterr().err.split())  # the message is wrapped at 100 columns
    assert "not a drumheat result folder" in err and "thesis.docx" in err
    assert sorted(p.name for p in (tmp_path / "mydata").rglob("*")) == before


@pytest.mark.parametrize("name", ["../../x", "", "a/b", ".hidden", ".."])
def test_scene_names_must_be_plain_file_names(name, tmp_path, monkeypatch, capsys):
    monkeypatch.chdir(tmp_path)
    with pytest.raises(SceneError, match="name"):
        load_scene("weigler-heating", {"name": name})
    assert main(["run", "weigler-heating", "--set", f"name={name}"] + QUICK) == 2
    assert list(tmp_path.iterdir()) == []


def test_file_symlink_and_readonly_targets_are_refused_before_the_run(tmp_path):
    f = tmp_path / "a_file"
    f.write_text("x")
    with pytest.raises(ResultFolderError, match="is a file"):
        check_out_dir(f)
    link = tmp_path / "dangling"
    link.symlink_to(tmp_path / "nowhere")
    with pytest.raises(ResultFolderError, match="symbolic link"):
        check_out_dir(link)
    if os.geteuid() != 0:  # root may write anywhere
        ro = tmp_path / "ro"
        ro.mkdir()
        ro.chmod(0o500)
        with pytest.raises(ResultFolderError, match="cannot be written"):
            check_out_dir(ro / "res")
        ro.chmod(0o700)


def test_a_result_folder_is_replaced_and_its_manifest_lists_its_files(result, tmp_path):
    out = tmp_path / "res"
    write_results(result, out, figures=False)
    listed = json.loads((out / MANIFEST).read_text())["files"]
    assert set(listed) == {p.name for p in out.iterdir()} - {MANIFEST}
    assert {"timeseries.csv", "summary.json", "particles.npz", "scene.toml"} <= set(listed)
    write_results(result, out, figures=False)  # an earlier result is replaced
    assert (out / "summary.json").exists()
    assert [p.name for p in tmp_path.iterdir()] == ["res"]  # no temporary folder left
    mask = os.umask(0)
    os.umask(mask)
    assert out.stat().st_mode & 0o777 == 0o777 & ~mask  # not 0700 whatever the umask


def test_user_files_inside_a_result_folder_block_its_replacement(result, tmp_path):
    out = tmp_path / "res"
    write_results(result, out, figures=False)
    (out / "my_notes.txt").write_text("keep me")
    with pytest.raises(ResultFolderError, match="my_notes.txt"):
        write_results(result, out, figures=False)
    assert (out / "my_notes.txt").read_text() == "keep me"
    assert (out / "summary.json").exists()


def test_an_animation_written_into_a_result_folder_is_registered(result, tmp_path):
    from drumheat.results.files import register_outputs

    out = tmp_path / "res"
    write_results(result, out, figures=False)
    (out / "animation.gif").write_bytes(b"GIF89a")
    register_outputs(out, ["animation.gif"])
    write_results(result, out, figures=False)  # replaced: the animation was drumheat's
    assert not (out / "animation.gif").exists()


def test_a_failing_write_keeps_the_earlier_result(result, tmp_path, monkeypatch):
    out = tmp_path / "res"
    write_results(result, out, figures=False)
    first = (out / "summary.json").read_text()

    def broken(*a, **k):
        raise RuntimeError("disk full")

    monkeypatch.setattr(type(result.timeseries), "to_csv", broken)
    with pytest.raises(RuntimeError, match="disk full"):
        write_results(result, out, figures=False)
    assert (out / "summary.json").read_text() == first
    assert [p.name for p in tmp_path.iterdir()] == ["res"]

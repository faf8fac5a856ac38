"""Animation of a result folder: GIF frames, MP4, command line and bad folders."""

import numpy as np
import pytest
from PIL import Image

from drumheat.results.animate import AnimationError, animate
from drumheat.cli import main
from drumheat.scene import load_scene


def write_result(folder, n_out=4, moving=False):
    """A small result folder: 12 particles in a 50 mm drum, n_out outputs."""
    folder.mkdir(parents=True, exist_ok=True)
    scene = load_scene("weigler-static")
    n = 12
    x = np.linspace(-0.018, 0.018, n)
    pos = np.stack([x, np.full(n, -0.015)], axis=1)
    t = np.arange(n_out) * 30.0
    position = np.repeat(pos[None], n_out, axis=0)
    if moving:
        position = position + np.array([0.0, 1e-4])[None, None, :] * t[:, None, None]
    T = 300.0 + np.linspace(0.0, 20.0, n)[None, :] + t[:, None] / 30.0
    np.savez_compressed(folder / "particles.npz", t=t, T=T, group=np.arange(n) % 2,
                        diameter=np.full(n, 0.004), position=position,
                        group_names=np.array(["cold", "warm"]))
    (folder / "scene.toml").write_text(scene.to_toml())
    return folder


def test_gif_has_one_frame_per_output(tmp_path):
    folder = write_result(tmp_path / "res", n_out=5, moving=True)
    out = animate(folder, fps=4)
    assert out == folder / "animation.gif"
    with Image.open(out) as im:
        assert im.n_frames == 5
        assert im.size == (600, 500)
        assert im.info["duration"] == 250
    assert not list(folder.glob(".*partial*"))


def test_gif_every_and_explicit_out(tmp_path):
    folder = write_result(tmp_path / "res", n_out=6)
    out = animate(folder, out=tmp_path / "sub" / "a.gif", every=2, dpi=50)
    with Image.open(out) as im:
        assert im.n_frames == 3


@pytest.mark.filterwarnings("ignore:os.fork:RuntimeWarning")
def test_mp4_or_clear_error(tmp_path):
    folder = write_result(tmp_path / "res", n_out=3)
    try:
        import imageio_ffmpeg
    except ImportError:
        imageio_ffmpeg = None
    if imageio_ffmpeg is None:
        with pytest.raises(AnimationError, match="gif"):
            animate(folder, fmt="mp4")
        return
    out = animate(folder, out=tmp_path / "a.mp4", fps=5)
    reader = imageio_ffmpeg.read_frames(str(out))
    meta = next(reader)
    assert sum(1 for _ in reader) == 3 and meta["fps"] == 5


def test_unknown_format(tmp_path):
    folder = write_result(tmp_path / "res", n_out=2)
    with pytest.raises(AnimationError, match="allowed"):
        animate(folder, out=tmp_path / "a.avi")
    with pytest.raises(AnimationError, match="does not end in .mp4"):
        animate(folder, out=tmp_path / "a.gif", fmt="mp4")


def test_cli_animate(tmp_path, capsys):
    folder = write_result(tmp_path / "res", n_out=3)
    assert main(["animate", str(folder), "--out", str(tmp_path / "x.gif"), "--fps", "2"]) == 0
    assert "x.gif" in capsys.readouterr().out
    with Image.open(tmp_path / "x.gif") as im:
        assert im.n_frames == 3


def test_cli_animate_bad_folder_exits_2(tmp_path, capsys):
    empty = tmp_path / "empty"
    empty.mkdir()
    assert main(["animate", str(empty)]) == 2
    err = capsys.readouterr().err
    assert "particles.npz" in err and "drumheat run" in err
    assert main(["animate", str(tmp_path / "missing")]) == 2
    assert "does not exist" in " ".join(capsys.readouterr().err.split())
    assert list(empty.iterdir()) == []


def test_cli_animate_bad_format_exits_2(tmp_path, capsys):
    folder = write_result(tmp_path / "res", n_out=2)
    assert main(["animate", str(folder), "--out", str(tmp_path / "a.avi")]) == 2
    assert "gif" in capsys.readouterr().err

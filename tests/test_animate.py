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


def test_3d_animation_shows_the_mid_depth_slice(tmp_path):
    """A 3D result animates the slice through the middle of the depth (as the snapshot figure
    draws it), not a projection of every bead; which beads the slice cuts changes per frame."""
    import matplotlib

    matplotlib.use("Agg")
    from drumheat.results import plot

    folder = tmp_path / "res3d"
    folder.mkdir()
    scene = load_scene("glass-drum-3d")
    rng = np.random.default_rng(0)
    n, n_out, depth = 300, 3, scene.drum.depth
    pos = np.stack([rng.uniform(-0.08, 0.08, (n_out, n)), rng.uniform(-0.1, 0.0, (n_out, n)),
                    rng.uniform(0.0, depth, (n_out, n))], axis=-1)
    T = 293.0 + 50.0 * rng.random((n_out, n))
    np.savez_compressed(folder / "particles.npz", t=np.arange(n_out) * 0.5, T=T,
                        group=np.zeros(n, int), diameter=np.full(n, 0.008), position=pos,
                        group_names=np.array(["glass"]))
    (folder / "scene.toml").write_text(scene.to_toml())
    frames = plot.read_particles(folder)
    counts = [len(plot.cross_section(frames, k)[0]) for k in range(n_out)]
    expected = [int(np.sum(np.abs(pos[k, :, 2] - 0.5 * depth) <= 0.004)) for k in range(n_out)]
    assert counts == expected and 0 < min(counts) < n
    out = animate(folder, fps=2, dpi=40)
    with Image.open(out) as im:
        assert im.n_frames == n_out

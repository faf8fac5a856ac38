"""The documentation site builds with `mkdocs build --strict`, without warnings, and its
scene reference (generated from drumheat/scene.py at build time) lists every scene key."""

import html
import os
import subprocess
import sys
from pathlib import Path

import pytest

ROOT = Path(__file__).resolve().parents[1]

pytest.importorskip("mkdocs", reason="mkdocs is not installed (pip install -e '.[docs]')")
pytest.importorskip("mkdocstrings", reason="mkdocstrings is not installed "
                                           "(pip install -e '.[docs]')")


@pytest.fixture(scope="module")
def site(tmp_path_factory):
    out = tmp_path_factory.mktemp("site")
    env = dict(os.environ, NO_MKDOCS_2_WARNING="1", PYTHONWARNINGS="ignore")
    proc = subprocess.run([sys.executable, "-m", "mkdocs", "build", "--strict",
                           "--config-file", str(ROOT / "mkdocs.yml"), "--site-dir", str(out)],
                          cwd=ROOT, capture_output=True, text=True, env=env, timeout=120)
    return out, proc


def test_mkdocs_build_strict_without_warnings(site):
    out, proc = site
    log = proc.stdout + proc.stderr
    assert proc.returncode == 0, log
    assert "WARNING" not in log, log
    assert (out / "index.html").is_file()
    for page in ("getting-started", "visualisation", "accuracy-vs-cost",
                 "models/thermal-network", "models/penetration", "api/plot"):
        assert (out / page / "index.html").is_file(), page


def test_scene_reference_lists_every_key(site):
    from drumheat.scene import iter_keys

    out, proc = site
    assert proc.returncode == 0
    text = html.unescape((out / "scene-reference" / "index.html").read_text())
    missing = [key for key, *_ in iter_keys() if key not in text]
    assert not missing, f"keys missing from the scene reference: {missing}"
    assert "[heat.contact]" in text and "W/(m2 K)" in text


def test_api_reference_renders_docstrings(site):
    out, _ = site
    text = (out / "api" / "plot" / "index.html").read_text()
    assert "plot_snapshot" in text and "draw_walls" in text
    assert "export_vtk" in (out / "api" / "vtk_export" / "index.html").read_text()

"""Every notebook in notebooks/ executes without error (nbclient, kernel python3)."""

from pathlib import Path

import nbformat
import pytest
from nbclient import NotebookClient

NOTEBOOKS = sorted((Path(__file__).resolve().parents[1] / "notebooks").glob("*.ipynb"))


def test_there_are_notebooks():
    assert len(NOTEBOOKS) >= 5


def test_notebooks_match_their_generator():
    """The .ipynb files are what notebooks/make_notebooks.py writes (edit that file, re-run it)."""
    import importlib.util

    gen = NOTEBOOKS[0].parent / "make_notebooks.py"
    spec = importlib.util.spec_from_file_location("make_notebooks", gen)
    mod = importlib.util.module_from_spec(spec)
    spec.loader.exec_module(mod)
    assert sorted(mod.NOTEBOOKS) == [p.name for p in NOTEBOOKS]
    for path in NOTEBOOKS:
        nb = nbformat.read(path, as_version=4)
        assert [c.source for c in nb.cells] == [c.source for c in mod.NOTEBOOKS[path.name]], (
            f"{path.name} differs from make_notebooks.py; run python notebooks/make_notebooks.py")


@pytest.mark.parametrize("path", NOTEBOOKS, ids=lambda p: p.name)
def test_notebook_executes(path, tmp_path):
    nb = nbformat.read(path, as_version=4)
    # run in a scratch folder: the result folders a notebook writes (results/...) stay out of
    # the checkout
    client = NotebookClient(nb, timeout=300, kernel_name="python3",
                            resources={"metadata": {"path": str(tmp_path)}})
    client.execute()  # raises CellExecutionError on the first failing cell
    errors = [o for c in nb.cells if c.cell_type == "code" for o in c.get("outputs", [])
              if o.get("output_type") == "error"]
    assert not errors

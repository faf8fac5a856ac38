"""The validation suite (drumheat.analysis.validation, ``drumheat validate``).

The references are written out here by hand where they are closed forms; the cases' tolerances
are the ones argued in the module (steady states to 1e-9: the transient left after
``steady_state`` is below 1e-13; adaptive transients at rtol = atol = 1e-10 to 1e-6).
"""

import math

import numpy as np
import pytest

import drumheat  # noqa: F401  (float64)
from drumheat.analysis import validation as v
from drumheat.cli import main
from drumheat.results.files import ResultFolderError

G = 57.0 * math.pi * 0.008**2 / 4


def test_chain_steady_reference_by_hand():
    # one sphere between two equal wall contacts sits at the mean of the walls
    T, Q = v.chain_steady_reference(1, G, 2 * G, 343.0, 293.0)
    assert T[0] == pytest.approx(318.0, abs=1e-12)
    assert Q == pytest.approx(50.0 * G, rel=1e-14)  # two resistances 1/(2G) in series
    # three equal resistances: thirds of the difference
    T, Q = v.chain_steady_reference(2, G, G, 343.0, 293.0)
    np.testing.assert_allclose(T, [343.0 - 50 / 3, 343.0 - 100 / 3], atol=1e-12)


def test_chain_eigen_reference_solves_the_chain_and_has_the_dirichlet_modes():
    n, C = 7, 0.5
    t = np.linspace(0.0, 2000.0, 5)
    T = v.chain_eigen_reference(n, G, G, C, 343.0, 293.0, t)
    np.testing.assert_allclose(T[0], 293.0, atol=1e-12)
    # for G_w = G the slowest mode decays with 4 G sin^2(pi / (2 (n + 1))) / C, and the
    # middle sphere approaches the wall with it once the next mode (8x faster) has gone
    lam1 = 4 * G * math.sin(math.pi / (2 * (n + 1))) ** 2 / C
    late = v.chain_eigen_reference(n, G, G, C, 343.0, 293.0, [4000.0, 5000.0])
    rate = math.log((343.0 - late[0, n // 2]) / (343.0 - late[1, n // 2])) / 1000.0
    assert rate == pytest.approx(lam1, rel=1e-6)


def test_case_chain_passes_its_tolerances():
    res = v.case_chain()
    assert len(res.rows) == 5
    for r in res.rows:
        assert r.status == "pass", (r.quantity, r.deviation, r.tolerance)


def test_lattice_conductivity_closed_forms():
    d = 0.008
    assert v.lattice_conductivity("sc", G, d) == pytest.approx(G / d, rel=1e-15)
    assert v.lattice_conductivity("bcc", G, d) == pytest.approx(math.sqrt(3) * G / d, rel=1e-15)
    assert v.lattice_conductivity("fcc", G, d) == pytest.approx(2 * math.sqrt(2) * G / d,
                                                                rel=1e-15)
    with pytest.raises(ValueError, match="lattice must be one of"):
        v.lattice_conductivity("hcp", G, d)


@pytest.mark.parametrize("lattice", ["sc", "bcc", "fcc"])
def test_lattice_bar_interior_conductivity_is_the_closed_form(lattice):
    r = v.lattice_bar(lattice, 6)
    assert r["lambda_interior"] == pytest.approx(r["lambda_ref"], rel=1e-9)
    assert r["spread"] < 1e-9  # each lattice plane is isothermal


def test_lattice_bar_wall_to_wall_is_series_resistances():
    # simple cubic: lambda_wall / lambda = n / (n - 1 + 2 G / G_w) for every n; exact for G_w = 2G
    for n in (4, 8):
        r = v.lattice_bar("sc", n, alpha_wp=1000.0)
        assert r["lambda_wall"] / r["lambda_ref"] == pytest.approx(n / (n - 1 + 2 * 57 / 1000),
                                                                   rel=1e-9)
    r = v.lattice_bar("sc", 5, alpha_wp=114.0)
    assert r["lambda_wall"] == pytest.approx(r["lambda_ref"], rel=1e-9)


def test_lattice_bar_refuses_a_box_that_merges_images():
    with pytest.raises(ValueError, match="take m >= 3"):
        v.lattice_bar("sc", 4, m=2)


def test_case_thesis_quick_passes():
    res = v.case_thesis(quick=True)
    assert [r.status for r in res.rows] == ["pass"] * 3
    heating = res.rows[1]
    # reference from the data file: mean of experiments 9-11 (27.0, 27.4, 27.0 degC)
    assert heating.reference == pytest.approx((27.0 + 27.4 + 27.0) / 3, abs=1e-12)


def test_unknown_case_is_refused():
    with pytest.raises(ValueError, match="unknown validation case"):
        v.run_validation(cases=["nope"], progress=None)


def test_table_and_folder(tmp_path):
    rows = [v.ValidationRow("x", "q", 1.0, 1.0 + 1e-12, "K", 1e-12, "rel", 1e-9, 0.1, "s"),
            v.ValidationRow("x", "r", 2.0, 2.5, "K", 0.25, "rel", None, 0.1, "s"),
            v.ValidationRow("x", "s", 2.0, 2.5, "K", 0.25, "rel", 0.1, 0.1, "s")]
    assert [r.status for r in rows] == ["pass", "reported", "FAIL"]
    text = v.format_table(rows)
    assert "reported" in text and "FAIL" in text
    md = v.format_table(rows, markdown=True)
    assert md.splitlines()[1].startswith("|---|")

    def fig(path):
        path.write_bytes(b"png")

    out = v.write_validation(rows, {"f.png": fig}, tmp_path / "val")
    assert sorted(p.name for p in out.iterdir()) == [".drumheat-files.json", "f.png",
                                                     "validation.csv", "validation.md"]
    v.write_validation(rows, {}, out)  # drumheat's own folder is replaced
    assert not (out / "f.png").exists()
    mine = tmp_path / "mine"
    mine.mkdir()
    (mine / "notes.txt").write_text("keep")
    with pytest.raises(ResultFolderError):
        v.write_validation(rows, {}, mine)
    assert (mine / "notes.txt").read_text() == "keep"


def test_cli_validate_quick_thesis(tmp_path, capsys):
    out = tmp_path / "val"
    assert main(["validate", "--quick", "--case", "thesis", "--out", str(out)]) == 0
    printed = capsys.readouterr().out
    assert "heating, T_mean at 60 s" in printed
    assert (out / "validation.csv").exists() and (out / "validation.md").exists()
    mine = tmp_path / "mine"
    mine.mkdir()
    (mine / "data.csv").write_text("1")
    assert main(["validate", "--quick", "--case", "thesis", "--out", str(mine)]) == 2
    assert main(["validate", "--quick", "--case", "nope"]) == 2


@pytest.mark.slow
def test_drum_pm_trends():
    """Full grid: faster rotation (shorter t_R) and a better wall contact both raise the
    semi-discrete alpha_overall, as the penetration model says (eqs. [1.6], [1.12])."""
    res = v.case_drum_pm(quick=False)
    by = {}
    for r in res.rows:
        if "rpm" in r.quantity:
            rpm = float(r.quantity.split(", ")[1].split(" rpm")[0])
            a_wp = float(r.quantity.rsplit("= ", 1)[1])
            by[(rpm, a_wp)] = r.drumheat
    for a_wp in (114.0, 1000.0, 10000.0):
        assert by[(3.0, a_wp)] < by[(10.0, a_wp)] < by[(30.0, a_wp)]
    for rpm in (3.0, 10.0, 30.0):
        assert by[(rpm, 114.0)] < by[(rpm, 1000.0)] < by[(rpm, 10000.0)]


@pytest.mark.slow
def test_full_suite_passes():
    rows, figures = v.run_validation(quick=False, progress=None)
    assert not [r.quantity for r in rows if r.status == "FAIL"]
    assert len(figures) == 4

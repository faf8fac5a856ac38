"""Tests of the sectional-drum bed geometry (reference/herz-sectional-drum.md)."""

import math

import jax
import matplotlib
import numpy as np
import pytest
from scipy.optimize import brentq

import drumheat  # noqa: F401  (enables float64)
from drumheat.models import sectional_drum as sd

matplotlib.use("Agg")

KEYS = ("P1", "P2", "Wo", "Wi", "l_SG")
BASE = dict(R1=0.25, R2=0.175 * 0.25, fill=0.30, gamma_deg=25.0)
ALPHA = math.pi / 4


def lengths(delta, **p):
    cl = sd.contact_lengths(delta, **p)
    return {k: np.asarray(getattr(cl, k)) for k in KEYS}


# ---------------------------------------------------------------------------------------------
# independent region-by-region construction of the source (Herz digest Sec. 2.1-2.3)
# ---------------------------------------------------------------------------------------------


def digest_construction(region, delta_deg, R1, R2, fill, gamma_deg):
    """Solve one region with the source's construction: one unknown (l or beta) on E, D from
    the quadratic (7)-(10) or from the line OC1, region area formula of the table in Sec. 2.3,
    and the unknown iterated (here: brentq) until the area equals A_bed (eq. 1)."""
    a = ALPHA
    d = math.radians(delta_deg)
    k = -math.tan(math.radians(gamma_deg))
    u1 = np.array([-math.cos(d), math.sin(d)])  # eq. 17
    u2 = np.array([-math.cos(d + a), math.sin(d + a)])
    C1, C2, B1, B2 = R1 * u1, R1 * u2, R2 * u1, R2 * u2
    A_sec = 0.5 * a * (R1**2 - R2**2)
    A_bed = fill * A_sec
    phi1 = math.pi - d
    phi2 = phi1 - a

    def in_range(P):
        ang = (math.atan2(P[1], P[0]) - phi2) % (2 * math.pi)
        return ang <= a + 1e-12 or ang >= 2 * math.pi - 1e-12

    def shell_point(E):  # eqs. (7)-(10), root chosen by polar angle in [phi2, phi1]
        x1, y1 = E
        A = 1 + k * k
        B = 2 * k * y1 - 2 * k * k * x1
        C = (k * x1 - y1) ** 2 - R1**2
        disc = B * B - 4 * A * C
        if disc < 0:
            return None
        for sgn in (+1, -1):
            x2 = (-B + sgn * math.sqrt(disc)) / (2 * A)
            P = np.array([x2, k * (x2 - x1) + y1])
            if in_range(P):
                return P
        return None

    def ray_point(E, u):  # surface line meets the plate line O + t u
        x1, y1 = E
        t = (y1 - k * x1) / (u[1] - k * u[0])
        return t * u, t

    def ang(P, Q):  # eq. (11)
        return math.acos(np.clip(P @ Q / (np.linalg.norm(P) * np.linalg.norm(Q)), -1, 1))

    def shoelace(*pts):  # eq. (21)
        x = np.array([p[0] for p in pts])
        y = np.array([p[1] for p in pts])
        return 0.5 * abs(np.dot(x, np.roll(y, -1)) - np.dot(y, np.roll(x, -1)))

    def evaluate(q):
        """Area and contact lengths for the region's unknown q (l or beta)."""
        if region in (1, 5):
            E = q * u1
        elif region in (3, 4, 7, 8):
            E = q * u2
        elif region == 2:
            E = R2 * np.array([-math.cos(d + q), math.sin(d + q)])
        else:  # 6
            E = R2 * np.array([-math.cos(d + a - q), math.sin(d + a - q)])
        if region in (4, 8):
            D, OD = ray_point(E, u1)
            if not R2 <= OD <= R1:
                return None
        else:
            D = shell_point(E)
            if D is None:
                return None
        l, beta = q, q
        L = dict(l_SG=float(np.linalg.norm(D - E)))
        if region == 1:
            th = ang(C1, D)
            area = 0.5 * R1**2 * th - 0.5 * R1 * l * math.sin(th)  # (14)
            L.update(Wo=R1 * th, Wi=0.0, P1=R1 - l, P2=0.0)
        elif region == 2:
            th = ang(C1, D)
            area = (shoelace(D, C1, B1, E) + 0.5 * R1**2 * (th - math.sin(th))
                    - 0.5 * R2**2 * (beta - math.sin(beta)))  # (21)-(25), erratum 3 applied
            L.update(Wo=R1 * th, Wi=R2 * beta, P1=R1 - R2, P2=0.0)
        elif region == 3:
            th = ang(C2, D)
            area = A_sec - (0.5 * R1**2 * th - 0.5 * R1 * l * math.sin(th))  # (31)-(34)
            L.update(Wo=R1 * (a - th), Wi=R2 * a, P1=R1 - R2, P2=l - R2)
        elif region == 4:
            area = 0.5 * OD * l * math.sin(a) - 0.5 * R2**2 * a  # (43)-(45)
            L.update(Wo=0.0, Wi=R2 * a, P1=OD - R2, P2=l - R2)  # (46), erratum 4 applied
        elif region == 5:
            th = ang(C1, D)
            area = A_sec - (0.5 * R1**2 * th - 0.5 * R1 * l * math.sin(th))
            L.update(Wo=R1 * (a - th), Wi=R2 * a, P1=l - R2, P2=R1 - R2)
        elif region == 6:
            th = ang(C2, D)
            area = (shoelace(D, C2, B2, E) + 0.5 * R1**2 * (th - math.sin(th))
                    - 0.5 * R2**2 * (beta - math.sin(beta)))
            L.update(Wo=R1 * th, Wi=R2 * beta, P1=0.0, P2=R1 - R2)
        elif region == 7:
            th = ang(C2, D)
            area = 0.5 * R1**2 * th - 0.5 * R1 * l * math.sin(th)
            L.update(Wo=R1 * th, Wi=0.0, P1=0.0, P2=R1 - l)
        else:  # 8
            area = 0.5 * R1**2 * a - 0.5 * OD * l * math.sin(a)
            L.update(Wo=R1 * a, Wi=0.0, P1=R1 - OD, P2=R1 - l)
        return area, L

    lo, hi = (0.0, a) if region in (2, 6) else (R2, R1)
    qs = np.linspace(lo, hi, 401)
    res = []
    for q in qs:
        ev = evaluate(q)
        res.append(np.nan if ev is None else ev[0] - A_bed)
    res = np.array(res)
    roots = []
    for i in range(len(qs) - 1):
        if np.isfinite(res[i]) and np.isfinite(res[i + 1]) and res[i] * res[i + 1] <= 0:
            roots.append(brentq(lambda q: evaluate(q)[0] - A_bed, qs[i], qs[i + 1], xtol=1e-15))
    assert len(set(np.round(roots, 12))) == 1, (region, delta_deg, roots)
    return evaluate(roots[0])[1]


def region_midpoints(**p):
    b = sd.region_boundaries(**p)
    mids = {}
    for b0, b1 in zip(b, b[1:] + [b[0]]):
        d1 = b1.delta_deg if b1.delta_deg > b0.delta_deg else b1.delta_deg + 360
        mids[b0.region_after] = (0.5 * (b0.delta_deg + d1)) % 360
    return mids


@pytest.mark.parametrize("gamma", [20.0, 25.0, 30.0])
def test_matches_source_region_construction(gamma):
    p = dict(BASE, gamma_deg=gamma)
    mids = region_midpoints(**p)
    assert sorted(mids) == list(range(1, 9))
    for region, delta in mids.items():
        assert int(sd.region_label(delta, **p)) == region
        ref = digest_construction(region, delta, **p)
        got = lengths(delta, **p)
        for k in KEYS:
            assert got[k] == pytest.approx(ref[k], abs=1e-10 * p["R1"]), (region, k)


# ---------------------------------------------------------------------------------------------
# area conservation
# ---------------------------------------------------------------------------------------------


@pytest.mark.parametrize(
    "p",
    [
        BASE,
        dict(R1=1.0, R2=0.0, fill=0.1, gamma_deg=35.0),
        dict(R1=1.0, R2=0.5, fill=0.7, gamma_deg=0.0),
        dict(R1=2.0, R2=0.3, fill=0.5, gamma_deg=-15.0, alpha_deg=60.0),
    ],
)
def test_bed_area_conserved_over_revolution(p):
    d = np.linspace(0.0, 360.0, 721)
    cl = sd.contact_lengths(d, **p)
    alpha_deg = p.get("alpha_deg", 45.0)
    A_bed = p["fill"] * float(sd.section_area(p["R1"], p["R2"], alpha_deg))
    A = np.asarray(sd.bed_area(d, cl.c, R1=p["R1"], R2=p["R2"], gamma_deg=p["gamma_deg"],
                               alpha_deg=alpha_deg))
    np.testing.assert_allclose(A, A_bed, rtol=1e-12)


def _polygon_area(P):
    x, y = P[:, 0], P[:, 1]
    return 0.5 * (np.dot(x, np.roll(y, -1)) - np.dot(y, np.roll(x, -1)))


@pytest.mark.parametrize("delta", [3.0, 20.0, 40.0, 90.0, 160.0, 200.0, 270.0, 300.0])
def test_clipped_polygon_area_and_edges_match(delta):
    """Sutherland-Hodgman clipping of a finely polygonised section is an independent check of
    the area and of every contact length (edges classified by the boundary they lie on)."""
    p = BASE
    R1, R2 = p["R1"], p["R2"]
    n_arc = 4000
    P = sd.bed_polygon(delta, **p, n_arc=n_arc)
    A_bed = p["fill"] * float(sd.section_area(R1, R2))
    assert _polygon_area(P) == pytest.approx(A_bed, rel=1e-6)

    g = math.radians(p["gamma_deg"])
    nvec = np.array([math.sin(g), math.cos(g)])
    c = float(sd.contact_lengths(delta, **p).c)
    phi1 = math.pi - math.radians(delta)
    u1 = np.array([math.cos(phi1), math.sin(phi1)])
    u2 = np.array([math.cos(phi1 - ALPHA), math.sin(phi1 - ALPHA)])
    got = dict.fromkeys(KEYS, 0.0)
    tol = 1e-9 * R1
    for a, b in zip(P, np.roll(P, -1, axis=0)):
        seg = np.linalg.norm(b - a)
        cross = lambda u, x: u[0] * x[1] - u[1] * x[0]  # noqa: E731
        if abs(a @ nvec - c) < tol and abs(b @ nvec - c) < tol:
            got["l_SG"] += seg
        elif abs(cross(u1, a)) < tol and abs(cross(u1, b)) < tol:
            got["P1"] += seg
        elif abs(cross(u2, a)) < tol and abs(cross(u2, b)) < tol:
            got["P2"] += seg
        elif abs(np.linalg.norm(a) - R1) < tol and abs(np.linalg.norm(b) - R1) < tol:
            got["Wo"] += seg
        elif abs(np.linalg.norm(a) - R2) < tol and abs(np.linalg.norm(b) - R2) < tol:
            got["Wi"] += seg
        else:
            raise AssertionError(f"unclassified edge {a} -> {b}")
    ref = lengths(delta, **p)
    for k in KEYS:
        # arcs are polygonal: chord/arc length error (dphi)^2/24 relative
        assert got[k] == pytest.approx(float(ref[k]), rel=1e-6, abs=1e-12), k


# ---------------------------------------------------------------------------------------------
# continuity across region boundaries
# ---------------------------------------------------------------------------------------------


def test_contact_lengths_continuous_across_boundaries():
    p = BASE
    bnds = sd.region_boundaries(**p)
    assert len(bnds) == 8
    h = 1e-6  # degrees
    d = np.array([b.delta_deg for b in bnds])
    lo, hi = lengths(d - h, **p), lengths(d + h, **p)
    for k in KEYS:
        # a Lipschitz constant of 10 R1 per radian gives 1.7e-7 R1 over 2h
        assert np.max(np.abs(hi[k] - lo[k])) < 2e-7 * p["R1"], k
    # and no jumps anywhere: halving the step halves the largest increment (kinks only)
    for n in (2880, 5760):
        g = np.linspace(0, 360, n + 1)
        L = lengths(g, **p)
        inc = max(np.max(np.abs(np.diff(L[k]))) for k in KEYS)
        if n == 2880:
            inc_coarse = inc
    assert inc < 0.6 * inc_coarse
    assert inc < 0.01 * p["R1"]


# ---------------------------------------------------------------------------------------------
# R2 = 0: plain drum segment and other closed forms
# ---------------------------------------------------------------------------------------------


@pytest.mark.parametrize("gamma", [0.0, 25.0])
@pytest.mark.parametrize("R2", [0.0, 0.1])
def test_plain_circular_segment(gamma, R2):
    """A small bed at the bottom of the section touches only the shell: it is a plain drum
    segment of central angle theta, with
        area  A    = 1/2 R^2 (theta - sin theta),
        arc   Wo   = R theta,
        chord l_SG = 2 R sin(theta / 2),
    independent of delta while the segment lies within the section (its centre is the
    direction -n, polar angle -90 deg - gamma; the section centre is at 180 - delta - 22.5)."""
    R = 1.0
    theta = 0.5  # rad, < alpha: fits between the plates
    A = 0.5 * R**2 * (theta - math.sin(theta))
    fill = A / float(sd.section_area(R, R2))
    delta_c = 247.5 + gamma
    margin = math.degrees(ALPHA - theta) / 2
    d = delta_c + np.array([-0.9, -0.5, 0.0, 0.5, 0.9]) * margin
    L = lengths(d, R1=R, R2=R2, fill=fill, gamma_deg=gamma)
    np.testing.assert_allclose(L["Wo"], R * theta, rtol=1e-12)
    np.testing.assert_allclose(L["l_SG"], 2 * R * math.sin(theta / 2), rtol=1e-12)
    np.testing.assert_allclose(L["P1"], 0, atol=1e-14)
    np.testing.assert_allclose(L["P2"], 0, atol=1e-14)
    np.testing.assert_allclose(L["Wi"], 0, atol=1e-14)
    # the pattern (shell only) is not one of the source's eight regions
    assert np.all(np.asarray(sd.region_label(d, R1=R, R2=R2, fill=fill, gamma_deg=gamma)) == 0)


@pytest.mark.parametrize("gamma", [0.0, 30.0])
def test_R2_zero_symmetric_positions(gamma):
    """R2 = 0, section symmetric about the surface normal.
    Bottom (delta = 247.5 + gamma, region 8): sector minus isosceles triangle,
        1/2 R^2 alpha - 1/2 rho^2 sin(alpha) = A_bed,  P1 = P2 = R - rho,
        l_SG = 2 rho sin(alpha/2),  Wo = R alpha.
    Top (delta = 67.5 + gamma, region-4-like apex): triangle at the axis,
        1/2 rho^2 sin(alpha) = A_bed,  P1 = P2 = rho,  l_SG = 2 rho sin(alpha/2),  Wo = 0."""
    R, f = 1.3, 0.3
    A_bed = f * 0.5 * ALPHA * R**2
    rho = math.sqrt((R**2 * ALPHA - 2 * A_bed) / math.sin(ALPHA))
    L = lengths(247.5 + gamma, R1=R, R2=0.0, fill=f, gamma_deg=gamma)
    assert float(L["P1"]) == pytest.approx(R - rho, rel=1e-12)
    assert float(L["P2"]) == pytest.approx(R - rho, rel=1e-12)
    assert float(L["l_SG"]) == pytest.approx(2 * rho * math.sin(ALPHA / 2), rel=1e-12)
    assert float(L["Wo"]) == pytest.approx(R * ALPHA, rel=1e-12)
    assert int(sd.region_label(247.5 + gamma, R1=R, R2=0.0, fill=f, gamma_deg=gamma)) == 8

    rho = math.sqrt(2 * A_bed / math.sin(ALPHA))
    L = lengths(67.5 + gamma, R1=R, R2=0.0, fill=f, gamma_deg=gamma)
    assert float(L["P1"]) == pytest.approx(rho, rel=1e-12)
    assert float(L["P2"]) == pytest.approx(rho, rel=1e-12)
    assert float(L["l_SG"]) == pytest.approx(2 * rho * math.sin(ALPHA / 2), rel=1e-12)
    assert float(L["Wo"]) == pytest.approx(0.0, abs=1e-14)


def test_R2_zero_region1_closed_form():
    """R2 = 0, region 1 (bed in the corner of plate 1 and the shell): the bed is the sector
    O C1 D minus the triangle O E D, so with theta = Wo/R and l = |OE| = R - P1 (eq. 14)
        A_bed = 1/2 R^2 theta - 1/2 R l sin(theta),
        l_SG  = |DE| = sqrt(R^2 + l^2 - 2 R l cos(theta))   (law of cosines)."""
    R, f, gamma = 1.0, 0.3, 25.0
    d = np.linspace(290, 359, 24)
    cl = sd.contact_lengths(d, R1=R, R2=0.0, fill=f, gamma_deg=gamma)
    assert np.all(np.asarray(cl.region) == 1)
    theta = np.asarray(cl.Wo) / R
    l = R - np.asarray(cl.P1)
    A14 = 0.5 * R**2 * theta - 0.5 * R * l * np.sin(theta)  # eq. (14)
    np.testing.assert_allclose(A14, f * 0.5 * ALPHA * R**2, rtol=1e-11)
    np.testing.assert_allclose(np.asarray(cl.l_SG),
                               np.sqrt(R**2 + l**2 - 2 * R * l * np.cos(theta)), rtol=1e-11)
    np.testing.assert_allclose(np.asarray(cl.P2), 0.0, atol=1e-14)


# ---------------------------------------------------------------------------------------------
# symmetries
# ---------------------------------------------------------------------------------------------


def test_repose_angle_only_shifts_the_curves():
    """A constant repose angle rotates the free surface; relative to gravity the whole picture
    turns by gamma, so every length obeys L(delta; gamma) = L(delta - dg; gamma - dg)."""
    d = np.linspace(0, 360, 97)
    a = lengths(d, **dict(BASE, gamma_deg=30.0))
    b = lengths(d - 12.0, **dict(BASE, gamma_deg=18.0))
    for k in KEYS:
        np.testing.assert_allclose(a[k], b[k], atol=1e-12 * BASE["R1"])


@pytest.mark.parametrize("gamma", [0.0, 20.0, 30.0])
def test_mirror_symmetry(gamma):
    """Mirroring about the vertical swaps the plates and gamma -> -gamma; combined with the
    shift above: P1(delta) = P2(135 + 2 gamma - delta), Wo, Wi, l_SG equal. Regions pair as
    1<->7, 2<->6, 3<->5, 4<->4, 8<->8 (Herz digest Sec. 2.2: 5/6 mirror 3/2, 7 like 1)."""
    p = dict(BASE, gamma_deg=gamma)
    d = np.linspace(0, 360, 73) + 0.123
    a = lengths(d, **p)
    b = lengths(135.0 + 2 * gamma - d, **p)
    atol = 1e-12 * p["R1"]
    np.testing.assert_allclose(a["P1"], b["P2"], atol=atol)
    np.testing.assert_allclose(a["P2"], b["P1"], atol=atol)
    for k in ("Wo", "Wi", "l_SG"):
        np.testing.assert_allclose(a[k], b[k], atol=atol)
    ra = np.asarray(sd.region_label(d, **p))
    rb = np.asarray(sd.region_label(135.0 + 2 * gamma - d, **p))
    pair = {0: 0, 1: 7, 2: 6, 3: 5, 4: 4, 5: 3, 6: 2, 7: 1, 8: 8}
    assert all(pair[int(x)] == int(y) for x, y in zip(ra, rb))
    m = sd.cycle_means(**p)
    assert m["P1"] == pytest.approx(m["P2"], rel=1e-10)


def test_half_turn_complement_symmetry():
    """A half turn maps the section onto itself rotated by 180 deg; the bed below the surface
    becomes the part above it, so with f -> 1 - f:
    P(delta + 180; f) = (R1 - R2) - P(delta; 1 - f), likewise Wo, Wi; l_SG is equal."""
    R1, R2 = BASE["R1"], BASE["R2"]
    d = np.linspace(0, 360, 61)
    a = lengths(d + 180.0, **BASE)
    b = lengths(d, **dict(BASE, fill=1 - BASE["fill"]))
    atol = 1e-11 * R1
    np.testing.assert_allclose(a["P1"], (R1 - R2) - b["P1"], atol=atol)
    np.testing.assert_allclose(a["P2"], (R1 - R2) - b["P2"], atol=atol)
    np.testing.assert_allclose(a["Wo"], R1 * ALPHA - b["Wo"], atol=atol)
    np.testing.assert_allclose(a["Wi"], R2 * ALPHA - b["Wi"], atol=atol)
    np.testing.assert_allclose(a["l_SG"], b["l_SG"], atol=atol)


def test_whole_drum_is_periodic_in_section_angle():
    d = np.linspace(0, 45, 11)
    a = sd.drum_contact_lengths(d, **BASE)
    b = sd.drum_contact_lengths(d + 45.0, **BASE)
    for k in KEYS + ("plates", "walls", "all_walls"):
        np.testing.assert_allclose(a[k], b[k], atol=1e-12)
    np.testing.assert_allclose(a["all_walls"], a["P1"] + a["P2"] + a["Wo"] + a["Wi"])


# ---------------------------------------------------------------------------------------------
# region boundaries (Herz digest Sec. 2.4); the values themselves are results, not asserted
# ---------------------------------------------------------------------------------------------

EVENTS = {  # transition into region r: which length hits which value (Sec. 2.4)
    2: ("P1", "full_plate"), 3: ("Wi", "full_inner"), 4: ("Wo", "zero"),
    5: ("P2", "full_plate"), 6: ("P1", "zero"), 7: ("Wi", "zero"),
    8: ("Wo", "full_shell"), 1: ("P2", "zero"),
}


@pytest.mark.parametrize("gamma", [20.0, 25.0, 30.0])
def test_region_boundaries_f30(gamma):
    p = dict(R1=1.0, R2=0.175, fill=0.30, gamma_deg=gamma)
    bnds = sd.region_boundaries(**p)
    print(gamma, [(round(b.delta_deg, 4), b.region_before, b.region_after) for b in bnds])
    assert len(bnds) == 8
    # topology: the cyclic sequence 1 -> 2 -> ... -> 8 -> 1
    for b in bnds:
        assert b.region_after == b.region_before % 8 + 1
    starts = {b.region_after: b.delta_deg for b in bnds}
    order = [starts[r] for r in range(1, 9)]
    k = int(np.argmin(order))
    rolled = order[k:] + [x + 360 for x in order[:k]]
    assert np.all(np.diff(rolled) > 0)
    # each boundary is the event of Sec. 2.4
    full = dict(full_plate=p["R1"] - p["R2"], full_inner=p["R2"] * ALPHA,
                full_shell=p["R1"] * ALPHA, zero=0.0)
    for r, (key, what) in EVENTS.items():
        val = float(lengths(starts[r], **p)[key])
        assert val == pytest.approx(full[what], abs=1e-11), (r, key)
    # mirror pairs sum to 135 + 2 gamma (mod 360): 1->2 with 6->7, 2->3 with 5->6, ...
    for r_in, r_mirror_in in ((2, 7), (3, 6), (4, 5), (8, 1)):
        s = (starts[r_in] + starts[r_mirror_in]) % 360
        assert s == pytest.approx((135 + 2 * gamma) % 360, abs=1e-7)


def test_region_boundaries_shift_with_gamma():
    base = dict(R1=1.0, R2=0.175, fill=0.30)
    b20 = [b.delta_deg for b in sd.region_boundaries(**base, gamma_deg=20.0)]
    b30 = [b.delta_deg for b in sd.region_boundaries(**base, gamma_deg=30.0)]
    np.testing.assert_allclose(np.sort(np.mod(np.array(b20) + 10.0, 360)), np.sort(b30), atol=1e-7)


# ---------------------------------------------------------------------------------------------
# cycle means and rates (Herz digest Sec. 5, eq. 48)
# ---------------------------------------------------------------------------------------------


def test_cycle_means_and_rates():
    m = sd.cycle_means(**BASE)
    d = np.linspace(0, 360, 20001)[:-1]
    L = lengths(d, **BASE)
    for k in KEYS:
        assert m[k] == pytest.approx(float(np.mean(L[k])), rel=2e-6), k
    assert m["all_walls"] == pytest.approx(m["P1"] + m["P2"] + m["Wo"] + m["Wi"])
    rates = sd.contact_length_rates(m, rpm=1.0)
    for k in m:
        assert rates[k] == pytest.approx(m[k] / 60.0)  # one revolution per 60 s
    # the whole drum's mean is eight times one section's
    dd = np.linspace(0, 45, 2001)[:-1]
    drum = sd.drum_contact_lengths(dd, **BASE)
    assert float(np.mean(drum["l_SG"])) == pytest.approx(8 * m["l_SG"], rel=1e-5)


# ---------------------------------------------------------------------------------------------
# plumbing
# ---------------------------------------------------------------------------------------------


def test_gradient_through_the_surface_solve():
    """The final Newton step makes jax.grad give the implicit-function derivative."""
    def f(fill):
        return sd.contact_lengths(40.0, R1=1.0, R2=0.175, fill=fill, gamma_deg=25.0).l_SG

    g = float(jax.grad(f)(0.3))
    h = 1e-6
    fd = (float(f(0.3 + h)) - float(f(0.3 - h))) / (2 * h)
    assert g == pytest.approx(fd, rel=1e-6)


def test_delta_at_time():
    assert float(sd.delta_at_time(10.0, rpm=1.0, delta0_deg=5.0)) == pytest.approx(65.0)


@pytest.mark.parametrize(
    "bad", [dict(R2=0.3), dict(fill=1.0), dict(fill=0.0), dict(gamma_deg=95.0), dict(R1=-1.0)]
)
def test_bad_input_raises(bad):
    p = dict(R1=0.25, R2=0.05, fill=0.3, gamma_deg=25.0, **{})
    p.update(bad)
    with pytest.raises(ValueError):
        sd.contact_lengths(10.0, **p)


def test_plots_return_figures():
    import matplotlib.figure

    fig = sd.plot_contact_lengths(**BASE, n=181)
    assert isinstance(fig, matplotlib.figure.Figure)
    assert len(fig.axes[0].lines) >= 5
    fig2 = sd.plot_bed(30.0, **BASE)
    assert isinstance(fig2, matplotlib.figure.Figure)
    import matplotlib.pyplot as plt

    plt.close("all")

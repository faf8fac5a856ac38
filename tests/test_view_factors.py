"""View factors and radiosity exchange (drumheat.models.view_factors)."""

import math

import jax
import jax.numpy as jnp
import numpy as np
import pytest
from scipy import integrate

import drumheat  # noqa: F401
from drumheat.models import view_factors as vf

SIG = 5.670374419e-8
DEG = math.pi / 180.0


# ------------------------------------------------------------------ sphere -> disc, solid angles


def _solid_angle_dblquad(h, a, rho):
    # Omega = int_disc h / |x - K|^3 dA, adaptive 2-D quadrature (independent of the module)
    f = lambda s, p: h * s / (h**2 + s**2 + rho**2 - 2 * s * rho * math.cos(p)) ** 1.5  # noqa: E731
    return integrate.dblquad(f, 0, 2 * math.pi, 0, a, epsabs=1e-12, epsrel=1e-12)[0]


def test_sphere_to_coaxial_disc_closed_form():
    for h, a in [(1.0, 1.0), (0.2, 3.0), (5.0, 0.5)]:
        F = 0.5 * (1 - 1 / math.sqrt(1 + (a / h) ** 2))  # Howell, sphere to coaxial disc
        assert float(vf.sphere_to_coaxial_disc(h, a)) == pytest.approx(F, rel=1e-14)
        assert float(vf.sphere_to_disc(h, a, 0.0)) == pytest.approx(F, rel=1e-12)


@pytest.mark.parametrize(
    "h,a,rho",
    [(1.0, 1.0, 0.5), (0.3, 1.0, 0.9), (0.3, 1.0, 0.999), (0.3, 1.0, 1.0), (0.3, 1.0, 1.001),
     (0.3, 1.0, 1.5), (2.0, 1.0, 3.0), (0.05, 1.0, 0.99), (0.05, 1.0, 1.01)],
)
def test_disc_solid_angle_off_axis(h, a, rho):
    assert float(vf.disc_solid_angle(h, a, rho)) == pytest.approx(_solid_angle_dblquad(h, a, rho), abs=1e-9)


def test_disc_solid_angle_limits_and_gradient():
    assert float(vf.disc_solid_angle(0.0, 1.0, 0.5)) == pytest.approx(2 * math.pi, rel=1e-12)
    assert float(vf.disc_solid_angle(1e-9, 1.0, 1.5)) == pytest.approx(0.0, abs=1e-7)
    # far field: Omega ~ pi a^2 h / D^3
    h, a, rho = 30.0, 1.0, 40.0
    D = math.hypot(h, rho)
    assert float(vf.disc_solid_angle(h, a, rho)) == pytest.approx(math.pi * a**2 * h / D**3, rel=1e-3)
    g = jax.grad(lambda rho: vf.disc_solid_angle(0.7, 1.0, rho))(0.4)
    fd = (_solid_angle_dblquad(0.7, 1.0, 0.4 + 1e-5) - _solid_angle_dblquad(0.7, 1.0, 0.4 - 1e-5)) / 2e-5
    assert float(g) == pytest.approx(fd, rel=1e-5)


# ------------------------------------------------------------------ granulator enclosure

# corners of regions A and B (staltner digest section 10), h3 = 1 m
CORNERS = [
    (r2, 1.0, h4, al)
    for (r2s, h4s) in [((2.0, 3.25), (0.75, 1.75)), ((3.25, 5.0), (1.0, 3.0))]
    for r2 in r2s
    for h4 in h4s
    for al in (45 * DEG, 60 * DEG)
]


@pytest.mark.parametrize("geom", CORNERS)
def test_granulator_summation_and_reciprocity(geom):
    F, A = vf.granulator_view_factors(*geom)
    F, A = np.asarray(F), np.asarray(A)
    np.testing.assert_allclose(F.sum(axis=1), 1.0, atol=1e-12)
    AF = A[:, None] * F
    np.testing.assert_allclose(AF, AF.T, rtol=1e-11, atol=1e-12)
    assert np.all(F >= -1e-14)
    assert F[0, 0] == 0.0 and F[3, 3] == 0.0


def test_granulator_hand_values():
    r2, h3, h4, al = 2.5, 1.0, 1.0, 50 * DEG
    t = math.tan(al)
    r5 = r2 - h4 / t
    H = h3 + h4
    s = math.sqrt(4 * r2**2 + h3**2)

    def Pi(a, b, L):  # coaxial discs, A_a F_ab, written out
        S = a * a + b * b + L * L
        return math.pi / 2 * (S - math.sqrt(S * S - 4 * a * a * b * b))

    A2, A3, A4 = math.pi * r2**2, 2 * math.pi * r2 * h3, math.pi * (r2**2 - r5**2) / math.cos(al)
    F, A = vf.granulator_view_factors(r2, h3, h4, al)
    assert float(F[0, 1]) == pytest.approx(h3 * (s - h3) / (2 * r2**2), rel=1e-13)  # B.3
    assert float(F[0, 3]) == pytest.approx(Pi(r2, r5, H) / A2, rel=1e-10)  # B.8
    assert float(F[1, 3]) == pytest.approx((Pi(r2, r5, h4) - Pi(r2, r5, H)) / A3, rel=1e-10)  # B.13
    S4 = r2**2 + r5**2 + h4**2
    assert float(F[2, 2]) == pytest.approx(1 - math.pi * (math.sqrt(S4**2 - 4 * r2**2 * r5**2) - h4**2) / A4, rel=1e-12)
    # phi45 printed with "+phi44~" is wrong; corrected: 1 - phi44 - phi44~
    f44t = (math.pi * r2**2 - Pi(r2, r5, h4)) / A4
    assert float(F[2, 3]) == pytest.approx(1 - float(F[2, 2]) - f44t, rel=1e-10)
    np.testing.assert_allclose(np.asarray(A), [A2, A3, A4, math.pi * r5**2], rtol=1e-14)


def test_frustum_limits():
    # r5 -> 0: full cone over its base, F_self = 1 - cos(alpha) (cone to base = r/slant = cos)
    r2, al = 2.0, 55 * DEG
    h4 = r2 * math.tan(al) * (1 - 1e-9)
    F, _ = vf.granulator_view_factors(r2, 1.0, h4, al)
    assert float(F[2, 2]) == pytest.approx(1 - math.cos(al), abs=1e-6)
    # alpha -> 90 deg: the frustum becomes a cylinder of height h4 (cylinder self view, B.10)
    r2, h4 = 2.0, 1.3
    F, _ = vf.granulator_view_factors(r2, 1.0, h4, 89.9999 * DEG)
    s4 = math.sqrt(4 * r2**2 + h4**2)
    assert float(F[2, 2]) == pytest.approx((2 * r2 + h4 - s4) / (2 * r2), abs=1e-5)


def test_granulator_geometry_refuses_closed_top():
    with pytest.raises(ValueError, match="r5"):
        vf.granulator_view_factors(2.0, 1.0, 3.0, 45 * DEG)


def _mc_zones_from_disc2(r2, h3, h4, al, n=400_000, seed=1):
    rng = np.random.default_rng(seed)
    r5 = r2 - h4 / math.tan(al)
    H = h3 + h4
    rr = r2 * np.sqrt(rng.random(n))
    th = 2 * np.pi * rng.random(n)
    x0, y0 = rr * np.cos(th), rr * np.sin(th)
    v = rng.random(n)  # cosine-weighted direction
    ph = 2 * np.pi * rng.random(n)
    st, ct = np.sqrt(v), np.sqrt(1 - v)
    dx, dy, dz = st * np.cos(ph), st * np.sin(ph), ct
    t1 = h3 / dz
    rad1 = np.hypot(x0 + t1 * dx, y0 + t1 * dy)
    t2 = H / dz
    rad2 = np.hypot(x0 + t2 * dx, y0 + t2 * dy)
    z3 = rad1 > r2
    z5 = (~z3) & (rad2 <= r5)
    z4 = (~z3) & (~z5)
    return np.array([0.0, z3.mean(), z4.mean(), z5.mean()])


def test_granulator_row2_monte_carlo():
    geom = (2.5, 1.0, 1.2, 55 * DEG)
    F, _ = vf.granulator_view_factors(*geom)
    mc = _mc_zones_from_disc2(*geom)
    np.testing.assert_allclose(np.asarray(F[0]), mc, atol=4 * math.sqrt(0.25 / 400_000))


# ------------------------------------------------------------------ sphere -> granulator zones


def _mc_zones_from_point(rho, z, r2, h3, h4, al, n=400_000, seed=2):
    rng = np.random.default_rng(seed)
    r5 = r2 - h4 / math.tan(al)
    H = h3 + h4
    d = rng.normal(size=(n, 3))
    d /= np.linalg.norm(d, axis=1, keepdims=True)
    x0, y0 = rho, 0.0

    def rad_at(zp):
        t = (zp - z) / d[:, 2]
        return np.hypot(x0 + t * d[:, 0], y0 + t * d[:, 1])

    zone = np.empty(n, dtype=int)
    down, up = d[:, 2] < 0, d[:, 2] > 0
    if z <= h3:
        zone[down] = np.where(rad_at(0.0)[down] <= r2, 2, 3)
        inside = rad_at(h3) <= r2
        zone[up] = np.where(~inside[up], 3, np.where(rad_at(H)[up] <= r5, 5, 4))
    else:
        inside = rad_at(h3) <= r2
        zone[down] = np.where(~inside[down], 4, np.where(rad_at(0.0)[down] <= r2, 2, 3))
        zone[up] = np.where(rad_at(H)[up] <= r5, 5, 4)
    return np.array([(zone == k).mean() for k in (2, 3, 4, 5)])


@pytest.mark.parametrize("rho,z", [(0.0, 0.5), (1.7, 0.3), (0.8, 1.5), (1.5, 1.9)])
def test_sphere_to_granulator_monte_carlo(rho, z):
    geom = (2.5, 1.0, 1.0, 50 * DEG)
    phi = np.asarray(vf.sphere_to_granulator_view_factors(rho, z, *geom))
    assert phi.sum() == pytest.approx(1.0, abs=1e-12)
    assert np.all(phi >= 0)
    mc = _mc_zones_from_point(rho, z, *geom)
    np.testing.assert_allclose(phi, mc, atol=4 * math.sqrt(0.25 / 400_000))


def test_sphere_to_granulator_on_axis_closed_form_and_batch():
    r2, h3, h4, al = 2.5, 1.0, 1.0, 50 * DEG
    r5 = r2 - h4 / math.tan(al)
    z = 0.4
    phi = np.asarray(vf.sphere_to_granulator_view_factors(0.0, z, r2, h3, h4, al))
    assert phi[0] == pytest.approx(0.5 * (1 - z / math.hypot(z, r2)), rel=1e-12)
    assert phi[3] == pytest.approx(0.5 * (1 - (2.0 - z) / math.hypot(2.0 - z, r5)), rel=1e-12)
    batch = vf.sphere_to_granulator_view_factors(jnp.array([0.0, 1.0, 2.0]), jnp.array([0.4, 1.5, 0.1]), r2, h3, h4, al)
    assert batch.shape == (3, 4)
    # differentiable in the geometry
    g = jax.jit(jax.grad(lambda a: vf.sphere_to_granulator_view_factors(1.0, 1.5, r2, h3, h4, a)[3]))(al)
    assert np.isfinite(float(g))


# ------------------------------------------------------------------ radiosity


def _two_surface(A1, A2, e1, e2, T1, T2):
    F = jnp.array([[0.0, 1.0], [A1 / A2, 1 - A1 / A2]])
    Q, _ = vf.radiosity_exchange(jnp.array([e1, e2]), jnp.array([A1, A2]), F, jnp.array([T1, T2]))
    return np.asarray(Q)


def test_concentric_spheres_closed_form():
    r1, r2, e1, e2, T1, T2 = 0.1, 0.3, 0.8, 0.4, 900.0, 400.0
    A1, A2 = 4 * math.pi * r1**2, 4 * math.pi * r2**2
    Q = _two_surface(A1, A2, e1, e2, T1, T2)
    ref = SIG * (T1**4 - T2**4) * A1 / (1 / e1 + (A1 / A2) * (1 / e2 - 1))
    assert Q[0] == pytest.approx(ref, rel=1e-12)
    assert Q[1] == pytest.approx(-ref, rel=1e-12)


def test_concentric_cylinders_closed_form():
    r1, r2, L, e1, e2, T1, T2 = 0.05, 0.2, 1.0, 0.6, 0.9, 300.0, 1200.0
    A1, A2 = 2 * math.pi * r1 * L, 2 * math.pi * r2 * L
    Q = _two_surface(A1, A2, e1, e2, T1, T2)
    ref = SIG * (T1**4 - T2**4) * A1 / (1 / e1 + (r1 / r2) * (1 / e2 - 1))
    assert Q[0] == pytest.approx(ref, rel=1e-12)


def test_black_enclosure_and_closure():
    F, A = vf.granulator_view_factors(3.0, 1.0, 1.5, 55 * DEG)
    T = jnp.array([900.0, 900.0, 373.15, 500.0])
    Q, H = vf.radiosity_exchange(jnp.ones(4), A, F, T)
    ref = [sum(float(A[i] * F[i, j]) * SIG * (float(T[i]) ** 4 - float(T[j]) ** 4) for j in range(4)) for i in range(4)]
    np.testing.assert_allclose(np.asarray(Q), ref, rtol=1e-10, atol=1e-6)
    # grey: the net flows of a closed enclosure sum to zero
    eps = jnp.array([0.9, 0.7, 0.5, 1.0])
    Q, _ = vf.radiosity_exchange(eps, A, F, T)
    assert float(jnp.sum(Q)) == pytest.approx(0.0, abs=1e-9 * float(jnp.max(jnp.abs(Q))))
    # eps/(1-eps) form of [3.41] for the grey surfaces
    Hg = np.asarray(vf.radiosity(eps, F, T))
    for i in range(3):
        e = float(eps[i])
        assert float(Q[i]) == pytest.approx(float(A[i]) * e / (1 - e) * (SIG * float(T[i]) ** 4 - Hg[i]), rel=1e-9)


def _granulator_case():
    geom = (3.0, 1.0, 1.5, 55 * DEG)
    F, A = vf.granulator_view_factors(*geom)
    phi = vf.sphere_to_granulator_view_factors(1.2, 1.6, *geom)
    eps_enc = jnp.array([0.9, 0.8, 0.7, 1.0])
    T_enc = jnp.array([1000.0, 1000.0, 373.15, 450.0])
    return F, A, phi, eps_enc, T_enc


def test_fictitious_view_factors_properties():
    F, A, phi, eps_enc, T_enc = _granulator_case()
    eps = jnp.concatenate([jnp.array([0.85]), eps_enc])
    Ffull = vf.particle_view_factor_matrix(phi, F)
    pt = np.asarray(vf.fictitious_view_factors(eps, Ffull))[0]
    assert pt[0] == pytest.approx(1.0, abs=1e-12)  # digest note: phi~_1 = 1
    assert np.all(pt[1:] <= 1e-15)  # phi~_j <= 0
    Ts = 1500.0
    T = jnp.concatenate([jnp.array([Ts]), T_enc])
    q_fict = float(jnp.sum(eps * SIG * pt * T**4))  # [6.37]-[6.40]
    q_red = float(vf.particle_radiative_flux(Ts, 0.85, phi, eps_enc, F, T_enc))
    assert q_fict == pytest.approx(q_red, rel=1e-11)
    # linearised form (digest section 4): h_r (T_s - T_rad) reproduces q exactly
    Trad = float(vf.radiation_sink_temperature(jnp.asarray(pt), eps, T))
    hr = float(vf.linearised_radiation_coefficient(Ts, Trad, 0.85))
    assert hr * (Ts - Trad) == pytest.approx(q_red, rel=1e-11)


def test_fictitious_matches_full_enclosure_with_small_particle():
    """A particle of finite but small area inside the enclosure (reciprocity-consistent)."""
    F, A, phi, eps_enc, T_enc = _granulator_case()
    Ts, e1 = 1500.0, 0.85
    q_red = float(vf.particle_radiative_flux(Ts, e1, phi, eps_enc, F, T_enc))
    errs = []
    for A1 in (1e-2, 1e-4):
        Fj1 = A1 * phi / A  # reciprocity
        Fenc = F * (1 - Fj1)[:, None]  # rows still sum to 1; reciprocity kept to O(A1)
        Ffull = jnp.block([[jnp.zeros((1, 1)), phi[None, :]], [Fj1[:, None], Fenc]])
        eps = jnp.concatenate([jnp.array([e1]), eps_enc])
        area = jnp.concatenate([jnp.array([A1]), A])
        Q, _ = vf.radiosity_exchange(eps, area, Ffull, jnp.concatenate([jnp.array([Ts]), T_enc]))
        errs.append(abs(float(Q[0]) / A1 - q_red) / abs(q_red))
    assert errs[1] < 1e-4 and errs[1] < errs[0]


def test_isothermal_enclosure():
    F, A, phi, eps_enc, _ = _granulator_case()
    Tw, Ts = 600.0, 1400.0
    q = float(vf.particle_radiative_flux(Ts, 0.85, phi, eps_enc, F, jnp.full(4, Tw)))
    assert q == pytest.approx(0.85 * SIG * (Ts**4 - Tw**4), rel=1e-12)

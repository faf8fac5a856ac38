"""Dry-air property fits (drumheat.models.air), staltner-slag-particle.md section 9."""

import warnings

import jax
import jax.numpy as jnp
import numpy as np
import pytest

import drumheat  # noqa: F401
from drumheat.models import air

# Table 4.6 coefficients written out again (independent of the module's table)
RHO = [4.298, -2.157e-2, 5.712e-5, -8.638e-8, 7.486e-11, -3.456e-14, 6.581e-18]
CP = [1010.685, 8.783e-2, -1.158e-3, 3.999e-6, -5.019e-9, 2.826e-12, -6.061e-16]
LAM = [-1.058e-3, 1.155e-4, -1.086e-7, 1.177e-10, -8.478e-14, 3.526e-17, -6.323e-21]
ETA = [-2.663e-7, 8.308e-8, -9.271e-11, 1.022e-13, -7.498e-17, 3.172e-20, -5.795e-24]


def _p(c, T):
    return sum(ci * T**i for i, ci in enumerate(c))


@pytest.mark.parametrize("T", [273.15, 300.0, 500.0, 800.0, 1273.15])
def test_fits_match_plain_python(T):
    assert float(air.density(T)) == pytest.approx(_p(RHO, T), rel=1e-12)
    assert float(air.heat_capacity(T)) == pytest.approx(_p(CP, T), rel=1e-12)
    assert float(air.conductivity(T)) == pytest.approx(_p(LAM, T), rel=1e-11)
    assert float(air.viscosity(T)) == pytest.approx(_p(ETA, T), rel=1e-11)
    assert float(air.kinematic_viscosity(T)) == pytest.approx(_p(ETA, T) / _p(RHO, T), rel=1e-11)
    assert float(air.prandtl(T)) == pytest.approx(_p(ETA, T) * _p(CP, T) / _p(LAM, T), rel=1e-11)
    p = air.properties(T)
    assert float(p.Pr) == pytest.approx(float(air.prandtl(T)), rel=1e-14)


# The digest tabulates no property values. These reference values are typed in from the VDI
# Heat Atlas dry-air table at 1 bar (the data the fits were made to, digest section 9); they are
# an outside check, hence the 1 % tolerance.
VDI = {
    # T (K): rho kg/m3, cp J/(kg K), lambda W/(m K), eta Pa s
    273.15: (1.275, 1006.0, 0.02436, 17.24e-6),
    293.15: (1.188, 1007.0, 0.02587, 18.21e-6),
    373.15: (0.9329, 1012.0, 0.03162, 21.94e-6),
}


@pytest.mark.parametrize("T", sorted(VDI))
def test_fits_against_vdi_values(T):
    rho, cp, lam, eta = VDI[T]
    assert float(air.density(T)) == pytest.approx(rho, rel=0.01)
    assert float(air.heat_capacity(T)) == pytest.approx(cp, rel=0.01)
    assert float(air.conductivity(T)) == pytest.approx(lam, rel=0.01)
    assert float(air.viscosity(T)) == pytest.approx(eta, rel=0.01)


def test_prandtl_range_as_digest_says():
    T = jnp.linspace(air.T_MIN, air.T_MAX, 201)
    Pr = np.asarray(air.prandtl(T))
    # digest section 5: "the Table 4.6 air gives Pr ~ 0.70-0.74"
    assert Pr.min() > 0.695 and Pr.max() < 0.745
    # monotone physical trends
    assert np.all(np.diff(np.asarray(air.density(T))) < 0)
    assert np.all(np.diff(np.asarray(air.conductivity(T))) > 0)
    assert np.all(np.diff(np.asarray(air.viscosity(T))) > 0)


def test_clamping_warns_and_clamps():
    with pytest.warns(UserWarning, match="outside the validity range"):
        v = air.conductivity(jnp.array([200.0, 300.0]))
    assert float(v[0]) == pytest.approx(_p(LAM, 273.15), rel=1e-12)
    with pytest.warns(UserWarning, match="clamped"):
        v = air.density(1500.0)
    assert float(v) == pytest.approx(_p(RHO, 1273.15), rel=1e-12)
    with pytest.warns(UserWarning):
        p = air.properties(2000.0)
    assert float(p.cp) == pytest.approx(_p(CP, 1273.15), rel=1e-12)


def test_no_warning_inside_range():
    with warnings.catch_warnings():
        warnings.simplefilter("error")
        air.properties(jnp.linspace(273.15, 1273.15, 11))


def test_warning_under_jit():
    f = jax.jit(air.viscosity)
    with pytest.warns(UserWarning, match="validity range"):
        f(jnp.array([250.0])).block_until_ready()
        jax.effects_barrier()


def test_gradient():
    g = float(jax.grad(air.conductivity)(600.0))
    fd = (_p(LAM, 600.0 + 1e-3) - _p(LAM, 600.0 - 1e-3)) / 2e-3
    assert g == pytest.approx(fd, rel=1e-6)


def test_constant_fallback_30c():
    c = air.AIR_30C
    assert float(c.lam) == 0.0266 and float(c.cp) == 1009.0
    assert float(c.rho) == pytest.approx(101325 * 28.96 / (8314 * 303.15), rel=1e-12)
    assert float(c.rho) == pytest.approx(1.1643, abs=1e-4)
    # the fits agree with the Weigler constants at 30 degC within 1 %
    assert float(air.conductivity(303.15)) == pytest.approx(c.lam, rel=0.01)
    assert float(air.heat_capacity(303.15)) == pytest.approx(c.cp, rel=0.01)
    assert float(air.density(303.15)) == pytest.approx(c.rho, rel=0.02)
    b = air.constant_properties(jnp.zeros((3,)))
    assert b.lam.shape == (3,)
    assert float(c.Pr) == pytest.approx(float(c.eta) * 1009.0 / 0.0266)

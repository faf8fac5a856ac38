"""Heat balances of the dry slag granulator's freeboard (Staltner 2018, chapter 7).

staltner-slag-particle.md section 8. Three control volumes, each with one unknown temperature:

* bed (WS) [7.7]: slag and bed air leave at T_WS (= T_2 = T_3, the bed and slot surfaces);
* cylindrical freeboard (FBZ) [7.12]: the slot air and the bed air mix to T_FB, the fluid
  temperature of the droplets' convection;
* conical freeboard (FBK) [7.16]: the air leaves at T_L,aus (= T_5, the outlet surface).

The slag terms are mass-weighted means over the size classes of the droplets' mean enthalpies
after Phase 1, at the FBK/FBZ boundary in Phase 3 (3*) and after Phase 3; the radiation is split
by path share [7.11]/[7.15]. The droplets depend on T_FB, T_WS and T_L,aus and these on the
droplets, so the source iterates to a fixed point; that loop runs the particle model and lives in
``scripts/staltner_balances.py``. This module holds the closed-form pieces: air streams, air
enthalpy, the wall-heat fit [4.8], and the three balances solved for their temperature.

Enthalpies are taken from T_B = 273.15 K [7.1]. The normal density rho_N of the air is not
given (digest section 12); 1.293 kg/m3 (0 degC, 1.01325 bar) is the default.
"""

from __future__ import annotations

from typing import Callable, NamedTuple

import numpy as np

from drumheat.models import air

__all__ = [
    "RHO_NORMAL",
    "T_BASE",
    "air_enthalpy",
    "air_temperature",
    "air_streams",
    "wall_heat",
    "radiation_split",
    "FreeboardState",
    "freeboard_state",
]

RHO_NORMAL = 1.293  # kg/m3 at 0 degC and 1.01325 bar (digest section 12: not stated)
T_BASE = 273.15  # K, T_B of [7.1]


def _cp_antiderivative(T):
    c = air.COEFFICIENTS["cp"]
    T = np.asarray(T, dtype=np.float64)
    return sum(ci * T ** (i + 1) / (i + 1) for i, ci in enumerate(c))


def air_enthalpy(T):
    """Specific enthalpy of dry air from T_B, J/kg: ``int_{T_B}^T c_pL dT`` [7.1].

    c_pL is the Tab. 4.6 polynomial (staltner-slag-particle.md section 9), integrated exactly.
    Valid for 273.15-1273.15 K (the fit's range); not clamped.
    """
    return _cp_antiderivative(T) - _cp_antiderivative(T_BASE)


def _invert(fn, target, lo, hi, iters=200):
    """Root of the increasing ``fn(T) = target`` in [lo, hi] by bisection (float64)."""
    lo, hi = float(lo), float(hi)
    if not fn(lo) <= target <= fn(hi):
        raise ValueError(f"target {target:.6g} outside [{fn(lo):.6g}, {fn(hi):.6g}] on "
                         f"[{lo:.2f}, {hi:.2f}] K")
    for _ in range(iters):
        mid = 0.5 * (lo + hi)
        if fn(mid) < target:
            lo = mid
        else:
            hi = mid
        if hi - lo < 1e-10:
            break
    return 0.5 * (lo + hi)


def air_temperature(h):
    """Inverse of :func:`air_enthalpy`, K (bisection in 273.15-1273.15 K)."""
    return _invert(lambda T: float(air_enthalpy(T)), float(h), air.T_MIN, air.T_MAX)


def air_streams(volume_flow_normal, bed_share, rho_normal=RHO_NORMAL):
    """Air mass flows (bed, slots, total) in kg/s, staltner-slag-particle.md section 8.

    ``m_L,WS = rho_N p_L,ges,WS V_L,ges,N``, ``m_L,SB = rho_N (1 - p) V``, ``m_L,ges`` the sum.

    Parameters
    ----------
    volume_flow_normal : V_L,ges,N in Nm3/h. bed_share : p_L,ges,WS (0-1).
    """
    V = volume_flow_normal / 3600.0
    m_ws = rho_normal * bed_share * V
    m_sb = rho_normal * (1.0 - bed_share) * V
    return m_ws, m_sb, m_ws + m_sb


def wall_heat(slag_rate):
    """Heat into the water-cooled wall, W: ``Q_W [MW] = 0.0036207 m_S[kg/min] - 0.1139`` [4.8]."""
    return (0.0036207 * slag_rate - 0.1139) * 1e6


def radiation_split(Q_phase1, Q_phase3, h3, h4):
    """(Q_Str,FBZ, Q_Str,FBK) from the radiation of Phases 1 and 3 by path share.

    [7.11]: ``Q_FBZ = 2 h3/(2 h3 + h4) Q_Str,3``; [7.15]: ``Q_FBK = Q_Str,1 + Q_Str,2 +
    h4/(2 h3 + h4) Q_Str,3`` with Q_Str,2 = 0 (staltner-slag-particle.md section 8).
    """
    s = 2.0 * h3 + h4
    return 2.0 * h3 / s * Q_phase3, Q_phase1 + h4 / s * Q_phase3


class FreeboardState(NamedTuple):
    """Solution of the three balances (K, W) and the residual of the total balance [7.18]."""

    T_bed: float
    T_freeboard: float
    T_outlet: float
    Q_wall: float
    Q_radiation: float
    Q_radiation_fbz: float
    Q_radiation_fbk: float
    total_residual: float


def freeboard_state(*, slag_rate, h_slag_0, h_slag_1, h_slag_3star, h_slag_3, Q_radiation_1,
                    Q_radiation_3, slag_enthalpy: Callable[[float], float], volume_flow_normal,
                    bed_share, T_air_in, h3, h4, rho_normal=RHO_NORMAL) -> FreeboardState:
    """T_WS, T_FB and T_L,aus from the balances [7.7], [7.12], [7.16] for given slag enthalpies.

    staltner-slag-particle.md section 8. All slag enthalpies are mass-weighted over the size
    classes (J/kg from T_B); the radiation Q_Str,1 and Q_Str,3 are heat flows (W, positive out of
    the slag): number flow of each class times the energy one droplet radiates in the phase.

    * [7.7]  ``m_S h3 + m_WS h_L,ein = m_S h_S(T_WS) + m_WS h_L(T_WS)`` for T_WS (bisection);
    * [7.12] ``m_SB h_L,ein + m_WS h_L(T_WS) + m_S h3* = m_ges h_L(T_FB) + m_S h3 + Q_FBZ``;
    * [7.16] ``m_ges h_L(T_FB) + m_S h0 = m_ges h_L(T_aus) + m_S h3* + Q_FBK + Q_W``;
    * [7.18] (their sum) is returned as a residual, W (round-off when the three hold).

    Parameters
    ----------
    slag_rate : m_S in kg/min (Tab. 8.1). slag_enthalpy : h_S(T) in J/kg from T_B.
    volume_flow_normal : Nm3/h. bed_share : p_L,ges,WS (0-1). T_air_in : K. h3, h4 : m.
    """
    m_s = slag_rate / 60.0
    m_ws, m_sb, m_tot = air_streams(volume_flow_normal, bed_share, rho_normal)
    h_in = float(air_enthalpy(T_air_in))
    Q_w = wall_heat(slag_rate)
    Q_fbz, Q_fbk = radiation_split(Q_radiation_1, Q_radiation_3, h3, h4)
    # [7.7]: m_S h_S(T) + m_WS h_L(T) increases with T
    bed = lambda T: m_s * float(slag_enthalpy(T)) + m_ws * float(air_enthalpy(T))
    T_ws = _invert(bed, m_s * h_slag_3 + m_ws * h_in, T_BASE, air.T_MAX)
    h_fb = (m_sb * h_in + m_ws * float(air_enthalpy(T_ws)) + m_s * (h_slag_3star - h_slag_3)
            - Q_fbz) / m_tot  # [7.12]
    T_fb = air_temperature(h_fb)
    h_aus = h_fb + (m_s * (h_slag_0 - h_slag_3star) - Q_fbk - Q_w) / m_tot  # [7.16]
    T_aus = air_temperature(h_aus)
    Q_str = Q_radiation_1 + Q_radiation_3
    # [7.18]: m_ges h_L,ein + m_S h_S,0 = m_ges h_L,aus + m_S h_S,WS + Q_W + Q_Str
    resid = (m_tot * h_in + m_s * h_slag_0 - m_tot * float(air_enthalpy(T_aus))
             - m_s * float(slag_enthalpy(T_ws)) - Q_w - Q_str)
    return FreeboardState(T_ws, T_fb, T_aus, Q_w, Q_str, Q_fbz, Q_fbk, resid)

"""Closed-form limit of a drum wall with heat capacity: two lumped capacities (wall, bed).

A thin wall (one temperature through its thickness, Biot number ``U s / lambda << 1``) around a
well-mixed bed (one bed temperature) is the linear system (derivation in
docs/models/drum-wall.md, "The analytic limit")::

    C_w dT_w/dt = P + U (T_o - T_w) - G (T_w - T_b) - H (T_w - T_g)
    C_b dT_b/dt = G (T_w - T_b)

with ``C_w``, ``C_b`` the heat capacities (J/K), ``U`` the conductance outside -> wall (W/K),
``P`` a prescribed heat flow into the wall (W), ``G`` the conductance wall -> bed (W/K) and
``H`` the conductance wall -> free gas (W/K). Written ``x' = A x + b`` with
``x = (T_w, T_b)``, its solution is ``x(t) = x_inf + exp(A t) (x_0 - x_inf)`` with the steady
state ``x_inf = -A^{-1} b`` and, by Sylvester's formula for a 2 x 2 matrix with distinct
eigenvalues ``l_1 != l_2``, ``exp(A t) = (e^{l_1 t} (A - l_2 I) - e^{l_2 t} (A - l_1 I)) /
(l_1 - l_2)``. ``A`` is similar to a symmetric negative-definite matrix (scale the rows by the
capacities), so both eigenvalues are real and negative, and distinct when ``G > 0`` and
``U + H > 0``.
"""

from __future__ import annotations

import numpy as np

__all__ = ["two_capacity_solution"]


def two_capacity_solution(t, C_w: float, C_b: float, U: float, G: float, *, T_o: float = 0.0,
                          P: float = 0.0, H: float = 0.0, T_g: float = 0.0, T_w0: float,
                          T_b0: float) -> tuple[np.ndarray, np.ndarray]:
    """Wall and bed temperature of the lumped two-capacity system (module docstring), K.

    Parameters
    ----------
    t : array_like
        Times, s.
    C_w, C_b : float
        Heat capacity of the wall and of the bed, J/K.
    U, G, H : float
        Conductances outside -> wall, wall -> bed and wall -> free gas, W/K.
    T_o, T_g : float
        Outside and gas temperature, K.
    P : float
        Prescribed heat flow into the wall (a flux times the area), W.
    T_w0, T_b0 : float
        Temperatures at t = 0, K.

    Returns
    -------
    (T_w, T_b) : arrays of the shape of ``t``

    Raises
    ------
    ValueError
        If ``G <= 0`` or ``U + H <= 0`` (no steady state: the closed form above needs both).
    """
    if G <= 0 or U + H <= 0:
        raise ValueError("two_capacity_solution needs G > 0 and U + H > 0 (a steady state)")
    t = np.asarray(t, float)
    A = np.array([[-(U + G + H) / C_w, G / C_w], [G / C_b, -G / C_b]])
    b = np.array([(P + U * T_o + H * T_g) / C_w, 0.0])
    x_inf = -np.linalg.solve(A, b)
    tr, det = np.trace(A), np.linalg.det(A)
    root = np.sqrt(tr * tr / 4.0 - det)
    l1, l2 = tr / 2.0 + root, tr / 2.0 - root
    dx = np.array([T_w0, T_b0]) - x_inf
    I2 = np.eye(2)
    v1 = (A - l2 * I2) @ dx / (l1 - l2)  # the mode e^{l_1 t}
    v2 = -(A - l1 * I2) @ dx / (l1 - l2)  # the mode e^{l_2 t}
    e1, e2 = np.exp(l1 * t), np.exp(l2 * t)
    return (x_inf[0] + v1[0] * e1 + v2[0] * e2, x_inf[1] + v1[1] * e1 + v2[1] * e2)

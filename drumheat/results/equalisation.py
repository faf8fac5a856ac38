"""When is a bed "equalised"? Three criteria, kept apart because they answer different questions.

A bed of a warm and a cold fraction in a chamber of gas temperature T_g (the thesis' equalisation
experiments, weigler-thermal-dem.md section 7.2) settles in two ways at once:

* **inside the bed** the particles exchange heat with each other through their contacts
  ([2.7], first term); this is what mixing speeds up;
* **the whole bed** drifts towards the chamber air through the lumped loss (αA)_WK ([2.7],
  third term), with the time constant m_p c / (αA)_WK (about 326 s for the 4 mm aluminium
  spheres, digest section 7.5), whatever the motion.

The experiment ran "until no colour change is visible" (digest section 7.2, step 5): a colour
stops changing only when the particle has reached its end state, which is the chamber
temperature, not the bed mean of the moment. So a time read off the experiment as "complete
equalisation" can be set by the drift to T_g rather than by the exchange inside the bed. This
module gives each criterion separately:

``"spread"``
    all particles within ``threshold`` of each other, ``max_i T_i - min_i T_i <= threshold``;
``"fraction_means"``
    the group means (mass-weighted, DESIGN.md ``T_mean:<group>``) within ``threshold`` of each
    other;
``"gas"``
    all particles within ``threshold`` of the gas temperature, ``max_i |T_i - T_g| <= threshold``
    (the end state of the chamber experiment).

Each time is the first output time from which on the criterion holds until the end of the run
(a criterion that is met, lost and met again counts from the last time it was met), or
``None`` when it does not hold at the end.
"""

from __future__ import annotations

from typing import Optional

import numpy as np

__all__ = ["settling_time", "equalisation_times"]


def settling_time(t, holds) -> Optional[float]:
    """The first time from which ``holds`` is true up to the end, or None.

    Parameters
    ----------
    t : array_like, shape (m,)
        Output times, s, increasing.
    holds : array_like of bool, shape (m,)
        Whether the criterion holds at each output time.
    """
    t = np.asarray(t, float)
    holds = np.asarray(holds, bool)
    if t.shape != holds.shape or t.ndim != 1:
        raise ValueError(f"t and holds must be 1-D of one length, got {t.shape} and {holds.shape}")
    if t.size == 0 or not holds[-1]:
        return None
    failing = np.flatnonzero(~holds)
    return float(t[0] if failing.size == 0 else t[failing[-1] + 1])


def equalisation_times(t, T, groups, mass, T_gas=None, threshold: float = 1.0) -> dict:
    """Equalisation times of a bed on the criteria of the module docstring.

    Main arguments
    --------------
    t : array_like, shape (m,)
        Output times, s.
    T : array_like, shape (m, N)
        Particle temperatures, K.
    groups : array_like of int, shape (N,)
        Group index of every particle.
    mass : array_like, shape (N,)
        Particle masses, kg (weights of the fraction means).

    Other arguments
    ---------------
    T_gas : float, optional
        Gas (chamber) temperature, K; without it there is no ``"gas"`` criterion.
    threshold : float
        K, > 0 (1 K: the thesis' temperature classes, digest section 8).

    Returns
    -------
    dict
        ``{"threshold_K", "spread", "fraction_means"[, "gas"]}`` with times in s or None.
    """
    if not threshold > 0:
        raise ValueError(f"threshold must be > 0 K, got {threshold}")
    T = np.asarray(T, float)
    groups = np.asarray(groups)
    mass = np.asarray(mass, float)
    out = {"threshold_K": float(threshold),
           "spread": settling_time(t, T.max(axis=1) - T.min(axis=1) <= threshold)}
    labels = np.unique(groups)
    means = np.stack([T[:, groups == g] @ mass[groups == g] / mass[groups == g].sum()
                      for g in labels], axis=1)
    out["fraction_means"] = settling_time(t, means.max(axis=1) - means.min(axis=1) <= threshold)
    if T_gas is not None:
        out["gas"] = settling_time(t, np.abs(T - float(T_gas)).max(axis=1) <= threshold)
    return out

"""The transfer area of a particle contact (weigler-thermal-dem.md section 4, eq. [2.7]).

Used by the contact conduction of the thermal network (:mod:`drumheat.thermal.contact`) and by
the per-step conduction in the DEM force loop (:mod:`drumheat.mechanics.conduction`).
"""

from __future__ import annotations

import jax.numpy as jnp

__all__ = ["projected_area"]


def projected_area(d_i, d_j):
    """Transfer area of a pair of diameters d_i, d_j: ``A_p = pi d^2 / 4`` of the smaller one.

    weigler-thermal-dem.md section 4 uses ``A_p = pi d_p^2 / 4`` for monodisperse beds (the PFC
    script takes the first ball's radius); for unequal sizes drumheat takes the smaller one, the
    neck of the heat bridge.
    """
    return 0.25 * jnp.pi * jnp.minimum(d_i, d_j) ** 2

"""Which contact kernel a DEM runs on: the JAX kernel or the C++ loop (``[dem] contact_backend``).

Both kernels implement the same contact law (:mod:`drumheat.mechanics.integrator`,
:mod:`drumheat.mechanics.cpu_kernel`; tests/test_cpu_kernel.py holds them equal to round-off).
The C++ loop serves single runs on the CPU (not an ensemble under ``vmap``, not a GPU); it is
compiled on first use and cached (:func:`drumheat.mechanics.cpu_kernel.available`).

``"auto"`` takes the C++ loop wherever it can serve and the JAX kernel elsewhere; ``"cpu"`` asks
for the C++ loop and falls back to JAX with one warning line where it cannot serve; ``"jax"``
always takes JAX.
"""

from __future__ import annotations

import warnings
from typing import NamedTuple

import jax

__all__ = ["BackendChoice", "CONTACT_BACKENDS", "choose_contact_backend"]

#: the values of ``[dem] contact_backend``
CONTACT_BACKENDS = ("auto", "jax", "cpu")


class BackendChoice(NamedTuple):
    """The kernel a DEM runs on (``"jax"`` or ``"cpu"``), what was asked for, and why the
    choice differs from the request (None when it does not)."""

    backend: str
    requested: str
    reason: str | None


def choose_contact_backend(requested: str, *, dim: int, params, dtype,
                           batched: bool = False, warn: bool = True) -> BackendChoice:
    """The contact kernel for a DEM.

    Main arguments
    --------------
    requested : {"auto", "jax", "cpu"}
        ``[dem] contact_backend``.
    dim, params, dtype :
        The DEM's dimension, :class:`~drumheat.mechanics.ContactParams` and float type (what
        :func:`drumheat.mechanics.cpu_kernel.unsupported_reasons` checks).

    Other arguments
    ---------------
    batched : bool
        The DEM runs under ``vmap`` (an ensemble): the C++ loop cannot serve.
    warn : bool
        Issue one ``RuntimeWarning`` line when ``"cpu"`` was asked for and cannot serve.
    """
    if requested not in CONTACT_BACKENDS:
        raise ValueError(f"contact_backend must be one of {CONTACT_BACKENDS}, got {requested!r}")
    if requested == "jax":
        return BackendChoice("jax", requested, None)
    from drumheat.mechanics import cpu_kernel

    reason = None
    if batched:
        reason = "the C++ contact loop serves single runs, not ensembles"
    elif jax.default_backend() != "cpu":
        reason = f"the C++ contact loop runs on the CPU, this run on {jax.default_backend()}"
    else:
        reasons = cpu_kernel.unsupported_reasons(dim, params, dtype, None)
        if reasons:
            reason = "; ".join(reasons)
        else:
            ok, why = cpu_kernel.available()
            if not ok:
                reason = why
    if reason is None:
        return BackendChoice("cpu", requested, None)
    if requested == "cpu" and warn:
        warnings.warn(f"dem.contact_backend = 'cpu' cannot be used ({reason}); running on the "
                      "JAX contact kernel (same contact law)", RuntimeWarning, stacklevel=2)
    return BackendChoice("jax", requested, reason)

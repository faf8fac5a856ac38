"""Exceptions raised by the DEM runner. Each carries the last good state (``.state``)."""

from __future__ import annotations


class DEMError(RuntimeError):
    """A DEM run stopped because its state became unphysical.

    Attributes:
      state: the last state that passed all checks (the start of the failing chunk), so a
        caller can inspect it, change a setting and resume from there.
      step: the step count of ``state``.
    """

    def __init__(self, message, state=None):
        super().__init__(message)
        self.state = state
        self.step = None if state is None else int(state.step)


class NonFiniteError(DEMError):
    """NaN or Inf in positions, velocities or forces."""


class ParticleEscapeError(DEMError):
    """A particle left the domain (the bounding box of the walls / neighbour-list box)."""


class OverlapError(DEMError):
    """An overlap exceeded the allowed fraction of the smaller radius."""


class NeighborListError(DEMError):
    """The neighbour list could not be (re)allocated large enough."""

"""What the mechanics' float type resolves in a DEM domain, and mixed precision.

The mechanics keep absolute positions in a float type (``make_dem(dtype=..., position_dtype=...)``,
a scene's ``[dem] precision``). A float resolves a coordinate x only to its spacing ``ulp(x)``
(for float32 between 2^-24 |x| and 2^-23 |x|), and the domain's largest coordinate sets the
coarsest spacing a particle meets. Two consequences follow from the set-up alone:

* The overlap of a contact, and with it the normal force ``k_n delta``, is resolved only to
  about the spacing of the coordinates the contact law reads. The natural scale to hold it
  against is the overlap under a particle's own weight, ``delta_g = m g / k_n`` (the lightest
  particle on the stiffest contact: the smallest such overlap of the scene): where the spacing
  reaches ``delta_g``, a resting contact cannot represent the force that carries one particle.
* A drift ``dt v`` smaller than half the spacing of the stored positions leaves a coordinate
  unchanged: a particle slower than ``ulp / (2 dt)`` along an axis does not move along it in a
  step (creep along the periodic axis of a long drum slice, the slowest motion of a bed, is
  lost first).

float64's spacing is 2^29 (5e8) times finer than float32's; its figures are reported for
completeness.

**Mixed precision** (``precision = "mixed"``: positions float64, everything else float32)
removes both where they bite, along the periodic axis of a long slice: the drift adds to
float64 positions, and the contact law reads the positions folded along the periodic axis to
a period ``fold_length = L / k`` (:func:`fold_length`, no longer than needed to keep that
axis's spacing at the cross-section's) and rounded to float32
(:meth:`drumheat.mechanics.forces.ContactForces.pair_positions`). Because ``fold_length``
divides ``L`` and exceeds twice the neighbour cutoff, the minimum image in ``fold_length`` of
two folded coordinates is the pair's separation, so every listed pair's geometry is what it
is unfolded, resolved to the spacing at ``fold_length`` rather than at ``L``. The axes across
the drum are not folded (the walls need their absolute coordinates): there mixed resolves what
float32 does. The measured effect of float32 and mixed on the built-in 3D drum and the speed
they buy are in docs/performance.md (precision).
"""

from __future__ import annotations

from typing import NamedTuple

import numpy as np

__all__ = ["PositionResolution", "fold_length", "position_resolution"]


class PositionResolution(NamedTuple):
    """What a float type resolves in a DEM domain (:func:`position_resolution`).

    Attributes:
      dtype: the mechanics' float type (``"float32"`` or ``"float64"``), the contact law's.
      spacing: per axis, the spacing of the coordinates the contact law reads at their largest
        absolute value (m): the domain's, or with mixed precision the folded periodic axis's.
      weight_overlap: ``m g / k_n`` of the lightest particle on the stiffest contact (m);
        None without gravity.
      slowest_speed: per axis, half the stored positions' spacing at the domain's largest
        coordinate over ``dt``: a particle slower than this along the axis does not move along
        it in a step (m/s).
      positions: the stored positions' float type (wider than ``dtype``: mixed precision).
    """

    dtype: str
    spacing: np.ndarray
    weight_overlap: float | None
    slowest_speed: np.ndarray
    positions: str

    @property
    def spacing_over_weight_overlap(self) -> float | None:
        """The coarsest spacing over ``m g / k_n`` (None without gravity): from 1 on, a
        resting contact cannot represent the force that carries one particle."""
        if self.weight_overlap is None:
            return None
        return float(np.max(self.spacing) / self.weight_overlap)

    def summary(self) -> dict:
        """The numbers as plain floats, for summary.json."""
        ratio = self.spacing_over_weight_overlap
        return {"mechanics": self.dtype, "positions": self.positions,
                "position_spacing_m": [float(u) for u in self.spacing],
                "weight_overlap_m": self.weight_overlap,
                "spacing_over_weight_overlap": ratio,
                "slowest_moving_speed_m_s": [float(v) for v in self.slowest_speed]}


def fold_length(periodic_length: float | None, cross_section: float, cutoff: float):
    """The period to which mixed precision folds the periodic axis (module docstring), or None
    (no periodic axis, or one too short to fold).

    ``L / k`` with the largest whole ``k`` that keeps it at least the larger of the
    cross-section's largest absolute coordinate ``cross_section`` (so that the folded axis is
    resolved as finely as the others, within a factor of two) and four neighbour cutoffs (so
    that the minimum image of every listed pair, closer than one cutoff, is unambiguous).
    """
    if periodic_length is None:
        return None
    k = int(float(periodic_length) // max(float(cross_section), 4.0 * float(cutoff)))
    return float(periodic_length) / k if k > 1 else None


def position_resolution(dtype, lo, hi, dt: float, m_min: float, k_max: float, gravity,
                        position_dtype=None, fold=None) -> PositionResolution:
    """What ``dtype`` resolves in the domain ``[lo, hi]`` (module docstring).

    Main arguments:
      dtype: the mechanics' float type.
      lo, hi: the corners of the domain the particles stay in (m), one value per axis.

    Other arguments:
      dt: the time step (s).
      m_min, k_max: the lightest particle's mass (kg) and the stiffest normal contact (N/m).
      gravity: the gravity vector (m/s^2).
      position_dtype: the stored positions' float type (default ``dtype``; wider: mixed
        precision).
      fold: with mixed precision, the period the last axis is folded to for the contact law
        (:func:`fold_length`; None: not folded).
    """
    dt_name = np.dtype(dtype).name
    pos_name = np.dtype(position_dtype or dtype).name
    extent = np.maximum(np.abs(np.asarray(lo, float)), np.abs(np.asarray(hi, float)))
    read = extent.copy()
    if fold is not None:
        read[-1] = fold  # the folded coordinates lie in [0, fold)
    spacing = np.spacing(read.astype(dt_name)).astype(float)
    drift = np.spacing(extent.astype(pos_name)).astype(float)
    g = float(np.linalg.norm(np.asarray(gravity, float)))
    weight = m_min * g / k_max if g > 0 else None
    return PositionResolution(dt_name, spacing, weight, drift / (2.0 * dt), pos_name)

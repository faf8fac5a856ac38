"""What the mechanics' float type resolves in a DEM domain.

The mechanics keep absolute positions in their float type (``make_dem(dtype=...)``, a scene's
``[dem] precision``). A float resolves a coordinate x only to its spacing ``ulp(x)`` (for
float32 between 2^-24 |x| and 2^-23 |x|), and the domain's largest coordinate sets the coarsest
spacing a particle meets. Two consequences follow from the set-up alone:

* The overlap of a contact, and with it the normal force ``k_n delta``, is resolved only to
  about the spacing. The natural scale to hold it against is the overlap under a particle's
  own weight, ``delta_g = m g / k_n`` (the lightest particle on the stiffest contact: the
  smallest such overlap of the scene): where the spacing reaches ``delta_g``, a resting
  contact cannot represent the force that carries one particle.
* A drift ``dt v`` smaller than half the spacing leaves a coordinate unchanged: a particle
  slower than ``ulp / (2 dt)`` along an axis does not move along it in a step (creep along the
  periodic axis of a long drum slice, the slowest motion of a bed, is lost first).

float64's spacing is 2^29 (5e8) times finer than float32's; its figures are reported for
completeness. The measured effect on the built-in 3D drum (float32 against float64 at N = 10 000
and 50 000) and the speed float32 buys are in docs/performance.md (precision).
"""

from __future__ import annotations

from typing import NamedTuple

import numpy as np

__all__ = ["PositionResolution", "position_resolution"]


class PositionResolution(NamedTuple):
    """What a float type resolves in a DEM domain (:func:`position_resolution`).

    Attributes:
      dtype: the mechanics' float type (``"float32"`` or ``"float64"``).
      spacing: per axis, the float spacing at the domain's largest absolute coordinate (m).
      weight_overlap: ``m g / k_n`` of the lightest particle on the stiffest contact (m);
        None without gravity.
      slowest_speed: per axis, ``spacing / (2 dt)``: a particle slower than this along the axis
        does not move along it in a step (m/s).
    """

    dtype: str
    spacing: np.ndarray
    weight_overlap: float | None
    slowest_speed: np.ndarray

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
        return {"mechanics": self.dtype,
                "position_spacing_m": [float(u) for u in self.spacing],
                "weight_overlap_m": self.weight_overlap,
                "spacing_over_weight_overlap": ratio,
                "slowest_moving_speed_m_s": [float(v) for v in self.slowest_speed]}


def position_resolution(dtype, lo, hi, dt: float, m_min: float, k_max: float,
                        gravity) -> PositionResolution:
    """What ``dtype`` resolves in the domain ``[lo, hi]`` (module docstring).

    Main arguments:
      dtype: the mechanics' float type.
      lo, hi: the corners of the domain the particles stay in (m), one value per axis.

    Other arguments:
      dt: the time step (s).
      m_min, k_max: the lightest particle's mass (kg) and the stiffest normal contact (N/m).
      gravity: the gravity vector (m/s^2).
    """
    dt_name = np.dtype(dtype).name
    extent = np.maximum(np.abs(np.asarray(lo, float)), np.abs(np.asarray(hi, float)))
    spacing = np.spacing(extent.astype(dt_name)).astype(float)
    g = float(np.linalg.norm(np.asarray(gravity, float)))
    weight = m_min * g / k_max if g > 0 else None
    return PositionResolution(dt_name, spacing, weight, spacing / (2.0 * dt))

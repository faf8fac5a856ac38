"""What a motion model hands back to the runner."""

from __future__ import annotations

from dataclasses import dataclass, field

import numpy as np


@dataclass
class Trajectory:
    """Particle temperatures and exchanged heat at the output times.

    Attributes
    ----------
    t : ndarray (n_out,)
        Output times, s.
    T : ndarray (n_out, N)
        Particle temperatures, K.
    Q : dict of ndarray (n_out,)
        Cumulative heat received from each outside reservoir ("wall", "gas", ...), J.
    position : ndarray (n_out, N, dim)
        Particle centres, m.
    diameter, mass, capacity : ndarray (N,)
        m, kg, J/K.
    group : ndarray of int (N,)
    n_contacts, n_wall_contacts : ndarray (n_out,)
        Particle-particle and particle-wall contacts at (or averaged over the interval ending
        at) each output time.
    wall_area : ndarray (n_out,)
        Transfer area of eq. [1.10], ``sum of d_p^2 over wall contacts`` (thesis App. A7), m2.
    extra : dict
        Further columns a motion model provides.
    stored_heat : ndarray (n_out,) or None
        Change of the stored heat since t = 0, J, where it is not ``sum m c (T - T0)``
        (particles with radial shells: from the shell enthalpies); used by the energy balance.
    files : dict
        Further result files: ``{file name: writer(path)}``, written by ``Result.save``.
    info : dict
        Further results of the motion model that are not time series (JSON-serialisable:
        numbers, strings, lists, dicts), e.g. the phase table of a granulator run or the
        steady-window evaluation of a channel; they go into ``summary.json`` under their keys.
    mechanics : dict
        Per-particle mechanics at the output times, for ParaView and
        :func:`drumheat.particle_table` (DEM motion models): ``velocity``, ``angular_velocity``,
        ``force``, ``coordination``, ``wall_contacts`` as ``(n_out, N, ...)`` float32 arrays
        (:func:`drumheat.mechanics.analysis.particle_mechanics`); NaN at outputs without
        mechanics (a replay). Empty for motion models without a DEM.
    drum_wall : dict
        A drum wall with heat capacity (``[heat.drum_wall]``): segment temperatures ``T``
        (n_out, n_seg) K, heat ``Q_outside`` in from outside and ``Q_gas`` out to the free gas
        since t = 0 (n_out,) J, segment ``capacity`` (n_seg,) J/K and ``area`` (n_seg,) m2.
        Empty without one.
    records : dict
        Further arrays of the run for analysis (e.g. the flow counters of a moving bed at the
        output times); not written to files.
    """

    t: np.ndarray
    T: np.ndarray
    Q: dict
    position: np.ndarray
    diameter: np.ndarray
    mass: np.ndarray
    capacity: np.ndarray
    group: np.ndarray
    n_contacts: np.ndarray
    n_wall_contacts: np.ndarray
    wall_area: np.ndarray
    extra: dict = field(default_factory=dict)
    stored_heat: np.ndarray | None = None
    files: dict = field(default_factory=dict)
    info: dict = field(default_factory=dict)
    records: dict = field(default_factory=dict)
    mechanics: dict = field(default_factory=dict)
    drum_wall: dict = field(default_factory=dict)

"""Motion model ``random``: the semi-discrete penetration model (weigler-thermal-dem.md 6.1, 6.5).

A fixed packing is heated through the wall; every rest period ``t_R`` (the penetration model's
rest time, eq. [1.1]) the bed is re-mixed instantly:

* ``remix = "permute"`` (the thesis' choice, section 6.1 item 3 and appendix A8, section 6.5):
  the particles are randomly re-distributed over the fixed positions (Matlab ``randperm``).
  Here this is done by moving the *particles*, not their temperatures: each particle keeps its
  temperature, heat capacity and group, and takes a new position; the contact network in
  particle numbering is rebuilt from the fixed packing's contacts. For a bed of equal particles
  this is exactly the thesis' permutation of the temperature vector over the positions, and it
  leaves every temperature untouched, so the stored heat ``sum m_i c_i T_i`` is unchanged
  bit for bit. **Unequal particles:** a position of the fixed packing has a size, so a particle
  may only take a position of its own (nominal) diameter; the permutation is drawn
  independently within each diameter class. Particles of equal size but different material
  (different ``m c``) may swap positions: capacity travels with the particle, so energy is
  still conserved exactly. Group means (``T_mean:<group>``) follow the particles.
* ``remix = "mean"`` (mentioned in section 6.1 as the less discrete alternative): every particle
  is set to the heat-capacity-weighted bed mean ``sum(C_i T_i) / sum(C_i)``; this conserves the
  stored heat to round-off (one floating-point division), and positions stay fixed.

Between re-mixings the balance [2.13]/[5.2] is integrated on the fixed network exactly as for
:class:`~drumheat.motion.static.StaticBed`. Re-mixing times are ``t_R, 2 t_R, ...`` strictly
before the last output time; output times need not coincide with them: the integration runs
piecewise over the union of both grids. An output at a re-mixing time records the state just
*before* the re-mix (for ``"permute"`` the temperatures are the same either side; only the
positions differ).

The permutations are drawn from ``numpy.random.default_rng([run.seed, 1])`` (stream 1 of the
run seed; the packing uses the seed itself), one after the other, so a run is reproducible and
the k-th re-mix does not depend on the output grid. They are static (not traced): ``solve`` is
differentiable with respect to every parameter in ``params`` (``jax.grad`` with the default
``autodiff = "reverse"``, ``jax.jacfwd`` with ``"forward"``).
"""

from __future__ import annotations

import jax.numpy as jnp
import numpy as np

from drumheat.assemble import group_index
from drumheat.motion.static import StaticBed, integrate_network, stack_states
from drumheat.runner.progress import SimProgress
from drumheat.scene import Scene
from drumheat.thermal.integrate import initial_state
from drumheat.thermal.network import ContactNetwork
from drumheat.motion.trajectory import Trajectory


class RandomBed(StaticBed):
    """Semi-discrete penetration model: a resting packing re-mixed every ``t_R``.

    weigler-thermal-dem.md sections 6.1 (item 3), 6.5 (appendix A8) and 11.1.

    Parameters
    ----------
    scene : Scene
        Needs ``[motion] model = "random"`` with ``t_R`` (s) and ``remix`` ("permute" or
        "mean"); ``run.seed`` seeds packing and permutations.

    Attributes
    ----------
    t_R : float
        Re-mixing period, s.
    remix : str
        "permute" or "mean".
    slot_diameter : ndarray (N,)
        Nominal diameter of every position of the packing, m (the permutation classes).
    """

    supports_particle_sharding = False

    def __init__(self, scene: Scene):
        super().__init__(scene)
        self.t_R = float(scene.motion.t_R)
        self.remix = scene.motion.remix
        self.slot_diameter = np.asarray(self.packing.diameter, float)
        self._classes = [np.flatnonzero(self.slot_diameter == d)
                         for d in np.unique(self.slot_diameter)]
        self._rng = np.random.default_rng([scene.run.seed, 1])
        self._perms: list[np.ndarray] = []
        self._pairs = np.asarray(self.pairs, dtype=np.int64).reshape(-1, 2)
        self._wall = np.asarray(self.wall_particles, dtype=np.int64)

    # -- re-mixing schedule -------------------------------------------------------------------
    def remix_times(self, t_end: float | None = None) -> np.ndarray:
        """Re-mixing times ``k t_R`` (k = 1, 2, ...) strictly before ``t_end`` (default: the
        last output time), s."""
        t_end = float(self.t_out[-1]) if t_end is None else float(t_end)
        k = int(np.floor(t_end / self.t_R * (1 + 1e-12)))
        t = self.t_R * np.arange(1, k + 1)
        # snap to output times that differ only by round-off (k t_R vs j dt_out)
        t_out = np.asarray(self.t_out, float)
        if len(t):
            nearest = t_out[np.argmin(np.abs(t_out[None, :] - t[:, None]), axis=1)]
            t = np.where(np.abs(nearest - t) <= 1e-12 * t, nearest, t)
        return t[t < t_end * (1 - 1e-12)]

    def permutation(self, k: int) -> np.ndarray:
        """The k-th re-mixing (k = 1, 2, ...) as a map of positions: after it, position ``s``
        holds the particle that was at position ``perm[s]`` before. Only positions of equal
        nominal diameter are exchanged."""
        while len(self._perms) < k:
            perm = np.arange(len(self.slot_diameter))
            for cls in self._classes:
                perm[cls] = cls[self._rng.permutation(len(cls))]
            self._perms.append(perm)
        return self._perms[k - 1]

    def owners(self, k: int) -> np.ndarray:
        """``owner[s]``: the particle at position ``s`` after ``k`` re-mixings (identity for k =
        0 or for ``remix = "mean"``)."""
        owner = np.arange(len(self.slot_diameter))
        if self.remix == "permute":
            for j in range(1, k + 1):
                owner = owner[self.permutation(j)]
        return owner

    def network(self, owner: np.ndarray) -> ContactNetwork:
        """The packing's contacts in particle numbering for the arrangement ``owner``."""
        pairs = owner[self._pairs] if len(self._pairs) else self._pairs
        return ContactNetwork.from_arrays(pairs, owner[self._wall])

    @staticmethod
    def mix_to_mean(T, capacity):
        """Every particle at the heat-capacity-weighted mean ``sum(C T) / sum(C)``, K.

        Conserves ``sum C_i T_i`` to round-off (remix = "mean", weigler section 6.1)."""
        return jnp.full_like(T, jnp.sum(capacity * T) / jnp.sum(capacity))

    # -- solve --------------------------------------------------------------------------------
    def _segments(self):
        """Rest periods as ``(k, grid)``: k re-mixings done before it; ``grid`` the times
        (period start, outputs inside, period end) to integrate over."""
        t_out = np.asarray(self.t_out, float)
        edges = np.concatenate([[t_out[0]], self.remix_times(t_out[-1]), [t_out[-1]]])
        segs = []
        for k, (a, b) in enumerate(zip(edges[:-1], edges[1:])):
            inside = t_out[(t_out > a) & (t_out < b)]
            segs.append((k, np.concatenate([[a], inside, [b]])))
        return segs

    def _run(self, params=None, progress: SimProgress | None = None):
        model, T0 = self.model(params)
        capacity = model.particles.capacity
        y = initial_state(model, T0)
        t_out = np.asarray(self.t_out, float)
        recorded = {0: y}
        owners_at = {0: np.arange(len(T0))}
        owner = np.arange(len(T0))
        segs = self._segments()
        for k, grid in segs:
            if k > 0:  # re-mix at the start of this period
                if self.remix == "permute":
                    owner = owner[self.permutation(k)]
                else:
                    y = {"T": self.mix_to_mean(y["T"], capacity), "Q": y["Q"]}
            states = integrate_network(self.scene, model, self.network(owner), y, grid,
                                       progress, autodiff=self.autodiff)
            for t, s in zip(grid[1:], states[1:]):
                idx = np.flatnonzero(t_out == t)
                if idx.size:
                    recorded[int(idx[0])] = s
                    owners_at[int(idx[0])] = owner
            y = states[-1]
        states = [recorded[i] for i in range(len(t_out))]
        return states, [owners_at[i] for i in range(len(t_out))], model

    def solve(self, params=None, progress: SimProgress | None = None):
        """Particle temperatures ``(n_out, N)`` (K, particles numbered as in the scene, not by
        position) and exchanged heat ``{account: (n_out,)}`` (J) at ``self.t_out``.

        Differentiable with respect to the values in ``params`` (dotted scene keys).
        """
        states, _, model = self._run(params, progress)
        return stack_states(states, model.accounts)

    def trajectory(self, params=None, progress: bool | None = True) -> Trajectory:
        """Run the scene; positions follow the particles through the re-mixings."""
        with SimProgress(self.scene.run.duration, progress) as bar:
            states, owners, model = self._run(params, bar)
        T, Q = stack_states(states, model.accounts)
        n_out = len(self.t_out)
        pos = self.packing.position
        # particle p sits at position slot_of[p] = argsort(owner)[p]
        position = np.stack([pos[np.argsort(o)] for o in owners])
        d = np.asarray(model.particles.diameter)
        return Trajectory(
            t=np.asarray(self.t_out), T=np.asarray(T), Q={k: np.asarray(v) for k, v in Q.items()},
            position=position, diameter=d, mass=np.asarray(model.particles.mass),
            capacity=np.asarray(model.particles.capacity), group=group_index(self.scene),
            n_contacts=np.full(n_out, len(self.pairs)),
            n_wall_contacts=np.full(n_out, len(self.wall_particles)),
            wall_area=np.full(n_out, float(np.sum(self.slot_diameter[self.wall_particles] ** 2))))

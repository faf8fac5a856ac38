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
the k-th re-mix does not depend on the output grid. They are drawn once when the model is built
and travel in the state as integer arrays, so a run is differentiable with respect to every
parameter in ``params`` and an ensemble over seeds is one vmapped program.
"""

from __future__ import annotations

import jax.numpy as jnp
import numpy as np

from drumheat.motion.base import register
from drumheat.motion.rows import stack_arrays
from drumheat.motion.static import StaticBed, polar_angle
from drumheat.motion.trajectory import Trajectory
from drumheat.scene import Scene
from drumheat.thermal.network import ContactNetwork
from drumheat.thermal.solvers import initial_state


@register
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

    name = "random"
    vmappable = True
    particle_shardable = False

    def __init__(self, scene: Scene):
        super().__init__(scene)
        self.t_R = float(scene.motion.t_R)
        self.remix = scene.motion.remix
        self.slot_diameter = np.asarray(self.packing.diameter, float)
        self._pairs = np.asarray(self.pairs, dtype=np.int64).reshape(-1, 2)
        self._wall = np.asarray(self.wall_particles, dtype=np.int64)
        self.perms = self.permutations(len(self.remix_times()), scene.run.seed)

    # -- re-mixing schedule -------------------------------------------------------------------
    def remix_times(self, t_end: float | None = None) -> np.ndarray:
        """Re-mixing times ``k t_R`` (k = 1, 2, ...) strictly before ``t_end`` (default: the
        last output time), s."""
        t_end = float(self.times[-1]) if t_end is None else float(t_end)
        k = int(np.floor(t_end / self.t_R * (1 + 1e-12)))
        t = self.t_R * np.arange(1, k + 1)
        # snap to output times that differ only by round-off (k t_R vs j dt_out)
        t_out = np.asarray(self.times, float)
        if len(t):
            nearest = t_out[np.argmin(np.abs(t_out[None, :] - t[:, None]), axis=1)]
            t = np.where(np.abs(nearest - t) <= 1e-12 * t, nearest, t)
        return t[t < t_end * (1 - 1e-12)]

    def permutations(self, n: int, seed: int) -> np.ndarray:
        """The first ``n`` re-mixings, shape (n, N): after the k-th (k = 1, 2, ...), position
        ``s`` holds the particle that was at position ``perms[k - 1, s]`` before. Only
        positions of equal nominal diameter are exchanged."""
        rng = np.random.default_rng([seed, 1])
        classes = [np.flatnonzero(self.slot_diameter == d) for d in np.unique(self.slot_diameter)]
        out = np.tile(np.arange(len(self.slot_diameter)), (n, 1))
        for k in range(n):
            for cls in classes:
                out[k, cls] = cls[rng.permutation(len(cls))]
        return out

    def permutation(self, k: int) -> np.ndarray:
        """The k-th re-mixing (k = 1, 2, ...) as a map of positions (:meth:`permutations`)."""
        perms = self.perms if k <= len(self.perms) else self.permutations(k, self.scene.run.seed)
        return perms[k - 1]

    @staticmethod
    def network(owner, contacts) -> ContactNetwork:
        """The packing's contacts in particle numbering for the arrangement ``owner``
        (``owner[s]``: the particle at position ``s``); ``contacts`` holds the packing's pairs
        and wall contacts as positions, with weights (0 marks padding)."""
        pairs, pw, wall, ww = (contacts[k] for k in ("pairs", "pair_weight", "wall",
                                                     "wall_weight"))
        return ContactNetwork(owner[pairs[:, 0]], owner[pairs[:, 1]], pw, owner[wall],
                              jnp.zeros(wall.shape[0], jnp.int32), ww,
                              contacts.get("wall_angle"))

    @staticmethod
    def mix_to_mean(T, capacity):
        """Every particle at the heat-capacity-weighted mean ``sum(C T) / sum(C)``, K.

        Conserves ``sum C_i T_i`` to round-off (remix = "mean", weigler section 6.1)."""
        return jnp.full_like(T, jnp.sum(capacity * T) / jnp.sum(capacity))

    def with_options(self, *, times=None, autodiff=None) -> "RandomBed":
        new = super().with_options(times=times, autodiff=autodiff)
        if times is not None:  # the re-mixings up to the new end
            new.perms = new.permutations(len(new.remix_times()), self.scene.run.seed)
        return new

    def align(self, states):
        """Pad the packings' contacts to common sizes (zero-weight slots)."""
        n_p = max(int(s["contacts"]["pairs"].shape[0]) for s in states)
        n_w = max(int(s["contacts"]["wall"].shape[0]) for s in states)

        def pad(a, n):
            return jnp.concatenate([a, jnp.zeros((n - a.shape[0],) + a.shape[1:], a.dtype)])

        return [dict(s, contacts={k: pad(v, n_p if k.startswith("pair") else n_w)
                                  for k, v in c.items()})
                for s, c in ((s, s["contacts"]) for s in states)]

    def shared(self) -> dict:
        return dict(super().shared(), **{"the re-mixing (motion.t_R, motion.remix)":
                                         (self.t_R, self.remix)})

    # -- the loop -----------------------------------------------------------------------------
    def initial_state(self, params=None):
        model, T0 = self.model(params)
        N = len(self.slot_diameter)
        contacts = {"pairs": jnp.asarray(self._pairs, jnp.int32).reshape(-1, 2),
                    "pair_weight": jnp.ones(len(self._pairs)),
                    "wall": jnp.asarray(self._wall, jnp.int32),
                    "wall_weight": jnp.ones(len(self._wall))}
        if model.drum_wall is not None:  # the positions' angles: the wall contacts' segments
            contacts["wall_angle"] = jnp.asarray(polar_angle(self.packing.position)[self._wall],
                                                 float)
        return {"model": model, "y": initial_state(model, T0), "contacts": contacts,
                "owner": jnp.arange(N, dtype=jnp.int32),
                "perms": jnp.asarray(self.perms, jnp.int32)}

    def advance(self, state, t0, t1):
        """Integrate [t0, t1], re-mixing at the start of every rest period inside it: the
        re-mix at ``k t_R`` happens at the start of the interval that begins there, so an
        output at ``k t_R`` shows the state just before it."""
        model, y, owner = state["model"], state["y"], state["owner"]
        remix = self.remix_times()
        cuts = remix[(remix > t0) & (remix < t1)]
        edges = np.concatenate([[t0], cuts, [t1]])
        for a, b in zip(edges[:-1], edges[1:]):
            k = int(np.searchsorted(remix, a, side="right"))  # re-mixings at or before a
            if k > 0 and remix[k - 1] == a:  # one at the start of this rest period
                if self.remix == "permute":
                    owner = owner[state["perms"][k - 1]]
                else:
                    y = dict(y, T=self.mix_to_mean(y["T"], model.particles.capacity))
            y = self.solve(model, self.network(owner, state["contacts"]), y, float(a),
                                    float(b))
        return dict(state, y=y, owner=owner)

    def observe(self, state) -> dict:
        return dict(super().observe(state), owner=state["owner"])

    def finish(self, rows, log, state) -> Trajectory:
        """Positions follow the particles through the re-mixings."""
        traj = super().finish(rows, log, state)
        owners = stack_arrays(rows, "owner", (r["owner"] for r in rows))
        pos = self.packing.position
        # particle p sits at position slot_of[p] = argsort(owner)[p]
        traj.position = np.stack([pos[np.argsort(o)] for o in owners])
        traj.wall_area = np.full(len(self.times),
                                 float(np.sum(self.slot_diameter[self.wall_particles] ** 2)))
        return traj

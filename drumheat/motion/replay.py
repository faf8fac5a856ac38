"""Motion model ``replay``: heat transfer on a recorded contact network, without mechanics.

Weigler's decoupled method (weigler-thermal-dem.md section 6.1, appendix A9): a mechanics run
writes its contacts, a thermal solver integrates eq. [2.13] on them. The thesis rebuilt a dense
N x N contact matrix per step, which limited it to about 4000 particles; here every recording
interval is a sparse pair list with contact durations (written by motion model ``dem`` with
``[dem] record_interval``), and each contact's conductance is weighted by the fraction of the
interval it existed. The temperatures take one explicit step per recording interval, the same
update the coupled run makes per thermal step, so replaying a recording with the coupled run's
thermal step reproduces that run's temperatures to round-off.

**Cyclic replay.** A recording of a few drum revolutions can be replayed over and over for
hours of process time (``[replay] cyclic = true``). At every restart the particles jump from
their end positions back to their recorded start positions; so that the temperature field stays
where it was in space, each particle's temperature is handed to the particle of the same group
whose start position best matches its end position (an optimal assignment). This is valid when
the recording covers the bed's steady motion (after start-up, several revolutions) and is long
against the mechanical mixing time, so that one cycle's contact statistics represent any other;
what it cannot represent is slow segregation or a drift of the bed state. The error against a
coupled run is measured by ``scripts/accuracy_cost.py``.
"""

from __future__ import annotations

import equinox as eqx
import jax
import jax.numpy as jnp
import numpy as np

from drumheat import assemble
from drumheat.motion.base import register
from drumheat.motion.static import ThermalBed
from drumheat.motion.trajectory import Trajectory
from drumheat.scene import Scene, SceneError
from drumheat.thermal.network import ContactNetwork

__all__ = ["Recording", "ReplayBed", "restart_assignment", "bisection_blocks", "squared_distances",
           "read_recording"]


def _pad_rows(ptr, col, fill):
    """The CSR column ``col`` (rows ``ptr[r]:ptr[r + 1]``) as a padded ``(rows, widest row)``
    array of its own dtype, filled with ``fill``. One column at a time, so that a recording
    (possibly memory-mapped) is never held padded in several columns at once beside the device
    arrays made of them."""
    k = len(ptr) - 1
    width = max(1, int(np.max(np.diff(ptr))) if k else 1)
    out = np.full((k, width), fill, np.asarray(col[:0]).dtype)
    for r in range(k):
        a, b = ptr[r], ptr[r + 1]
        out[r, : b - a] = col[a:b]
    return out


#: largest group (particles) whose restart assignment is solved over all its particles at once;
#: larger groups are cut into blocks of at most this many (:func:`restart_assignment`)
ASSIGNMENT_BLOCK = 2048


def restart_assignment(end_pos, start_pos, group, block: int = ASSIGNMENT_BLOCK) -> np.ndarray:
    """Particle whose temperature each particle takes at a cyclic restart.

    ``match[b] = a``: particle b, back at its recorded start position, takes the temperature of
    particle a of the same group whose end position is closest: an optimal assignment of
    squared distances (scipy's ``linear_sum_assignment``) per group.

    A group of more than ``block`` particles is first cut into blocks by recursive median
    bisection (:func:`bisection_blocks`), and the assignment is optimal within each block. The
    dense assignment needs a ``(n, n)`` cost matrix and up to O(n^3) time, which a group of
    50 000 particles cannot afford (20 GB); the blocks keep both to O(n block) (a block's
    matrix is 32 MB at the default 2048). The start and end positions are two samples of the
    same bed, so the two halves of a cut cover the same region up to about a particle spacing,
    and the field is carried over as closely (the cost against the optimum is measured in
    docs/models/replay.md).
    """
    from scipy.optimize import linear_sum_assignment

    end_pos, start_pos = np.asarray(end_pos, float), np.asarray(start_pos, float)
    match = np.arange(len(group))
    for g in np.unique(group):
        idx = np.nonzero(group == g)[0]
        for b, a in bisection_blocks(start_pos[idx], end_pos[idx], block):
            rows, cols = linear_sum_assignment(squared_distances(start_pos[idx[b]],
                                                                 end_pos[idx[a]]))
            match[idx[b[rows]]] = idx[a[cols]]
    return match


def squared_distances(x, y) -> np.ndarray:
    """``(len(x), len(y))`` squared distances, one axis at a time: two such arrays alive at
    once instead of the three-times larger ``(len(x), len(y), dim)`` differences (the same
    sums in the same order)."""
    out = np.zeros((len(x), len(y)))
    for k in range(x.shape[1]):
        d = x[:, k, None] - y[None, :, k]
        d *= d
        out += d
    return out


def bisection_blocks(start, end, block: int) -> list:
    """Cut two equal-sized point sets into blocks of at most ``block`` points of each.

    Each cut splits both sets at their median along the axis on which the two together extend
    furthest, the same number of points of each on each side (the lower ``n // 2`` of both go
    to one side), and is repeated until a block holds at most ``block``. Returns a list of
    ``(b, a)`` index arrays into ``start`` and ``end`` of equal length, covering each set once.
    """
    n = len(start)
    if len(end) != n or block < 1:
        raise ValueError(f"bisection_blocks needs equal sets and block >= 1, got {n}, "
                         f"{len(end)}, {block}")
    todo, blocks = [(np.arange(n), np.arange(n))], []
    while todo:
        b, a = todo.pop()
        if len(b) <= block:
            blocks.append((b, a))
            continue
        both = np.concatenate([start[b], end[a]])
        axis = int(np.argmax(np.ptp(both, axis=0)))
        h = len(b) // 2
        ob, oa = np.argpartition(start[b, axis], h), np.argpartition(end[a, axis], h)
        todo += [(b[ob[:h]], a[oa[:h]]), (b[ob[h:]], a[oa[h:]])]
    return blocks


class Recording:
    """A recorded contact network as padded device arrays (one row per recording interval).

    Parameters
    ----------
    first : int
        First recorded interval to keep (the cycle is intervals ``first .. K-1``).
    rec : dict
        The arrays of ``contacts.npz`` (see :class:`drumheat.motion.dem.DEMBed`): ``interval``,
        ``n_particles``, ``pair_ptr/pair_i/pair_j/pair_duration``, ``wall_ptr/wall_particle/
        wall_index/wall_duration``, ``wall_heated``, ``positions`` (K + 1, N, dim), ``group``.
    """

    def __init__(self, rec: dict, first: int = 0):
        if first:  # keep intervals first..K-1 (e.g. leave out a start-up from rest)
            rec = dict(rec)
            pp, wp = rec["pair_ptr"], rec["wall_ptr"]
            for key in ("pair_i", "pair_j", "pair_duration"):
                rec[key] = rec[key][pp[first]:]
            for key in ("wall_particle", "wall_index", "wall_duration"):
                rec[key] = rec[key][wp[first]:]
            rec["pair_ptr"], rec["wall_ptr"] = pp[first:] - pp[first], wp[first:] - wp[first]
            rec["positions"] = rec["positions"][first:]
        self.tau = float(rec["interval"])
        self.n_intervals = len(rec["pair_ptr"]) - 1
        self.n = int(rec["n_particles"])
        pp = rec["pair_ptr"]
        w = _pad_rows(pp, np.asarray(rec["pair_duration"], float), 0.0)
        w /= self.tau  # the contact-time fractions, in place
        # padding index n: ContactNetwork
        self.pairs = (jnp.asarray(_pad_rows(pp, rec["pair_i"], self.n), jnp.int32),
                      jnp.asarray(_pad_rows(pp, rec["pair_j"], self.n), jnp.int32),
                      jnp.asarray(w, float))
        del w
        heated = np.asarray(rec["wall_heated"], float)[rec["wall_index"]]
        # wall id of each contact (drums with internals book each surface separately)
        ids = (np.asarray(rec["wall_ids"], np.int32)[rec["wall_index"]] if "wall_ids" in rec
               else np.zeros(len(rec["wall_index"]), np.int32))
        wp = rec["wall_ptr"]
        self.walls = (jnp.asarray(_pad_rows(wp, rec["wall_particle"], 0), jnp.int32),
                      jnp.asarray(_pad_rows(wp, rec["wall_duration"] / self.tau * heated, 0.0),
                                  float),
                      jnp.asarray(_pad_rows(wp, ids, 0), jnp.int32))
        # as recorded (float32; memory-mapped from a run's result folder): 12 instead of 24
        # bytes per particle and interval; restart_assignment and position_at work in float64
        self.positions = np.asarray(rec["positions"])
        self.span = self.tau * self.n_intervals
        self.mean_pairs = float(np.sum(rec["pair_duration"])) / self.span
        self.mean_wall = float(np.sum(rec["wall_duration"] * heated)) / self.span
        self.match = restart_assignment(self.positions[-1], self.positions[0],
                                        np.asarray(rec["group"]))
        self.net = RecordedNetwork(self.pairs, self.walls, jnp.asarray(self.match), self.tau,
                                   self.n_intervals)

    def network(self, k) -> ContactNetwork:
        """Contact network of interval ``k`` (weights = contact-time fractions)."""
        return self.net.network(k)

    def position_at(self, g: int) -> np.ndarray:
        """Positions at the start of (cyclic) interval ``g``."""
        return np.asarray(self.positions[g % self.n_intervals], float)


class RecordedNetwork(eqx.Module):
    """The device part of a :class:`Recording`: the padded per-interval networks and the
    restart assignment, with the replay step (a PyTree, so it can travel in a run's state).

    pairs: (i, j, weight) arrays (K, P); walls: (particle, weight, wall id) arrays (K, W);
    match: (N,) restart assignment; tau: recording interval, s; n_intervals: K.
    """

    pairs: tuple
    walls: tuple
    match: jax.Array
    tau: float = eqx.field(static=True)
    n_intervals: int = eqx.field(static=True)

    def network(self, k) -> ContactNetwork:
        """Contact network of interval ``k`` (weights = contact-time fractions)."""
        i, j, w = (a[k] for a in self.pairs)
        wp, ww, wid = (a[k] for a in self.walls)
        return ContactNetwork(i, j, w, wp, wid, ww)

    def advance(self, model, T, Q, g, n_steps: int):
        """``n_steps`` explicit steps of one recording interval each from the cyclic interval
        counter ``g``: ``(T, Q, g)`` after them. A step whose counter is a positive multiple
        of the number of intervals first carries the temperatures over to the restart
        positions (:func:`restart_assignment`)."""
        return _replay_steps(self, model, T, Q, g, int(n_steps))


@eqx.filter_jit
def _replay_steps(net: RecordedNetwork, model, T, Q, g, n_steps):
    C = model.particles.capacity
    K, tau = net.n_intervals, net.tau

    def step(carry, _):
        T, Q, g = carry
        k = g % K
        T = jnp.where((k == 0) & (g > 0), T[net.match], T)
        q, ext = model.heat_flows(T, net.network(k))
        return (T + tau * q / C, {a: Q[a] + tau * ext[a] for a in Q}, g + 1), None

    return jax.lax.scan(step, (T, Q, g), None, length=n_steps)[0]


def read_recording(path) -> dict:
    """The arrays of a ``contacts.npz`` recording."""
    with np.load(path) as f:
        return {k: f[k] for k in f.files}


@register
class ReplayBed(ThermalBed):
    """Thermal-only replay of a recorded contact network (see the module docstring).

    The state is ``{"model", "T", "Q", "g"}`` (``g`` the cyclic recording-interval counter).
    The scene checks that the recording exists and fits (:mod:`drumheat.scene.rules`).
    """

    name = "replay"
    vmappable = True

    def __init__(self, scene: Scene):
        super().__init__(scene)
        raw = read_recording(assemble.resolve_path(scene, scene.replay.file))
        self.group = assemble.group_index(scene)
        raw["group"] = self.group
        self.rec = Recording(raw)
        self.diameter = raw["diameter"]
        self.steps_per_output = int(round(scene.run.output_interval / self.rec.tau))
        self._check_step(self.model()[0])

    def _check_step(self, model) -> None:
        """Refuse a recording interval above the explicit thermal limit of its own networks
        (weigler eq. [2.2]): the replay takes one explicit step per interval."""
        net = self.rec.net
        g = jax.vmap(lambda k: model.conductance_sum(net.network(k)))(
            jnp.arange(net.n_intervals))
        G = jnp.max(g, axis=0)
        limit = float(jnp.min(jnp.where(G > 0, model.particles.capacity / jnp.where(
            G > 0, G, 1.0), jnp.inf)))
        if self.rec.tau > limit:
            raise SceneError("replay.file", self.scene.replay.file,
                             f"its recording interval {self.rec.tau:g} s exceeds the explicit "
                             f"thermal limit {limit:.3g} s of its contact networks with this "
                             "scene's coefficients (weigler eq. [2.2]): record with a shorter "
                             "dem.record_interval or check the coefficients", self.scene.name)

    def initial_state(self, params=None):
        model, T0 = self.model(params)
        return {"model": model, "T": jnp.asarray(T0, float),
                "Q": {a: jnp.zeros(()) for a in model.accounts},
                "g": jnp.asarray(0, jnp.int64)}

    def advance(self, state, t0, t1):
        n = int(round((t1 - t0) / self.rec.tau))
        T, Q, g = self.rec.net.advance(state["model"], state["T"], state["Q"], state["g"], n)
        return dict(state, T=T, Q=Q, g=g)

    def observe(self, state) -> dict:
        return {"T": state["T"], "Q": state["Q"]}

    def shared(self) -> dict:
        return dict(super().shared(), **{"the recording (replay.file)": self.scene.replay.file})

    def finish(self, rows, log, state) -> Trajectory:
        r = self.stack_rows(rows)
        model = state["model"]
        n_out = len(self.times)
        rec = self.rec
        d2 = float(np.mean(self.diameter**2))
        return Trajectory(
            t=np.asarray(self.times), T=r["T"], Q=r["Q"],
            position=np.stack([rec.position_at(m * self.steps_per_output) for m in range(n_out)]),
            diameter=self.diameter, mass=np.asarray(model.particles.mass),
            capacity=np.asarray(model.particles.capacity), group=self.group,
            n_contacts=np.full(n_out, rec.mean_pairs), n_wall_contacts=np.full(n_out, rec.mean_wall),
            wall_area=np.full(n_out, d2 * rec.mean_wall))

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

import functools

import equinox as eqx
import jax
import jax.numpy as jnp
import numpy as np

from drumheat import assemble
from drumheat.devices import to_device
from drumheat.motion.base import register
from drumheat.motion.npz_files import release_pages
from drumheat.motion.static import ThermalBed
from drumheat.motion.trajectory import Trajectory
from drumheat.scene import Scene, SceneError
from drumheat.thermal.network import ContactNetwork

__all__ = ["Recording", "ReplayBed", "restart_assignment", "bisection_blocks", "squared_distances",
           "read_recording"]


def _pad_rows(ptr, row_values, fill, rows, width: int, dtype) -> np.ndarray:
    """Rows ``rows`` of a CSR column (row r: positions ``ptr[r]:ptr[r + 1]``) as a padded
    ``(len(rows), width)`` array of ``dtype`` filled with ``fill``; ``row_values(a, b)`` gives
    the values of positions ``a:b`` (a slice of the column, or a quantity made of it). One
    column and one row at a time, so that a recording (possibly memory-mapped) is never held
    padded in several columns at once."""
    out = np.full((len(rows), width), fill, dtype)
    for s, r in enumerate(rows):
        a, b = int(ptr[r]), int(ptr[r + 1])
        out[s, : b - a] = row_values(a, b)
    return out


def _widest(ptr) -> int:
    """The most entries of one row of a CSR column (at least 1: a padded array is never empty)."""
    return max(1, int(np.max(np.diff(ptr))) if len(ptr) > 1 else 1)


#: bytes of recorded networks that :meth:`Recording.replay` puts on the device at once; a block
#: of intervals of at most this size (at least one interval) per device call
REPLAY_BLOCK_BYTES = 32 * 2**20


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


def squared_distances(x, y, rows: int = 256) -> np.ndarray:
    """``(len(x), len(y))`` squared distances, one axis at a time and ``rows`` rows of ``x`` at
    a time: besides the result, one ``(rows, len(y))`` temporary instead of the three-times
    larger ``(len(x), len(y), dim)`` differences (the same sums in the same order)."""
    out = np.zeros((len(x), len(y)))
    d = np.empty((min(rows, len(x)), len(y)))
    for r0 in range(0, len(x), rows):
        blk, tmp = out[r0:r0 + rows], d[:min(rows, len(x) - r0)]
        for k in range(x.shape[1]):
            np.subtract(x[r0:r0 + rows, k, None], y[None, :, k], out=tmp)
            tmp *= tmp
            blk += tmp
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
    """A recorded contact network: the recording's arrays on the host, and its intervals as
    padded device arrays (one row per interval) where the replay needs them.

    :attr:`net` puts the whole cycle on the device (the motion model ``replay``, whose variants
    of an ensemble share it); :meth:`replay` (the replay after ``dem.replay_after``) does so
    too where the cycle fits in :data:`REPLAY_BLOCK_BYTES`, and else puts a block of intervals
    at a time there, so that it holds at most that much of networks instead of the cycle's.
    Both give the same rows, and so the same temperatures.

    Parameters
    ----------
    rec : dict
        The arrays of ``contacts.npz`` (see :class:`drumheat.motion.dem.DEMBed`): ``interval``,
        ``n_particles``, ``pair_ptr/pair_i/pair_j/pair_duration``, ``wall_ptr/wall_particle/
        wall_index/wall_duration``, ``wall_heated``, ``positions`` (K + 1, N, dim), ``group``.
        They are kept as given (memory maps stay memory maps).
    first : int
        First recorded interval to keep (the cycle is intervals ``first .. K-1``).
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
        self._rec = rec
        self._heated = np.asarray(rec["wall_heated"], float)
        # wall id of each contact (drums with internals book each surface separately)
        self._wall_ids = (np.asarray(rec["wall_ids"], np.int32) if "wall_ids" in rec
                          else np.zeros(len(self._heated), np.int32))
        self.pair_width, self.wall_width = _widest(rec["pair_ptr"]), _widest(rec["wall_ptr"])
        # as recorded (float32; memory-mapped from a run's result folder): 12 instead of 24
        # bytes per particle and interval; restart_assignment and position_at work in float64
        self.positions = np.asarray(rec["positions"])
        self.span = self.tau * self.n_intervals
        self.mean_pairs = float(np.sum(rec["pair_duration"])) / self.span
        self.mean_wall = float(np.sum(rec["wall_duration"] * self._heated[rec["wall_index"]])
                               ) / self.span
        self.match = restart_assignment(self.positions[-1], self.positions[0],
                                        np.asarray(rec["group"]))
        self._match = to_device(self.match)
        self._release()

    def _release(self) -> None:
        """Give back the resident pages of the recording's memory maps (a run's result folder:
        :func:`~drumheat.motion.npz_files.release_pages`), which every read of them leaves in
        the process's memory for as long as the recording lives; nothing for arrays in memory."""
        for value in self._rec.values():
            release_pages(value)

    def __repr__(self) -> str:  # stable: it is part of a replay state's structure
        return f"Recording({self.n_intervals} intervals of {self.tau:g} s, {self.n} particles)"

    @functools.cached_property
    def net(self) -> RecordedNetwork:
        """The whole cycle's networks on the device (built at the first use, then kept)."""
        return self.networks(0, self.n_intervals)

    def networks(self, g, n: int) -> RecordedNetwork:
        """The networks of the ``n`` cyclic intervals from counter ``g`` (rows ``(g + s) mod K``,
        each padded to the cycle's widest interval, so every block has the same row layout)."""
        rec, tau = self._rec, self.tau
        rows = (int(g) + np.arange(int(n))) % self.n_intervals
        pp, wp = rec["pair_ptr"], rec["wall_ptr"]
        pi, pj, pd = rec["pair_i"], rec["pair_j"], rec["pair_duration"]
        wpart, wi, wd = rec["wall_particle"], rec["wall_index"], rec["wall_duration"]
        pad = functools.partial(_pad_rows, rows=rows)
        # padding index n: ContactNetwork; weights: the contact-time fractions
        pairs = (to_device(pad(pp, lambda a, b: pi[a:b], self.n, width=self.pair_width,
                               dtype=np.int32)),
                 to_device(pad(pp, lambda a, b: pj[a:b], self.n, width=self.pair_width,
                               dtype=np.int32)),
                 to_device(pad(pp, lambda a, b: np.asarray(pd[a:b], float) / tau, 0.0,
                               width=self.pair_width, dtype=float)))
        walls = (to_device(pad(wp, lambda a, b: wpart[a:b], 0, width=self.wall_width,
                               dtype=np.int32)),
                 to_device(pad(wp, lambda a, b: wd[a:b] / tau * self._heated[wi[a:b]], 0.0,
                               width=self.wall_width, dtype=float)),
                 to_device(pad(wp, lambda a, b: self._wall_ids[wi[a:b]], 0,
                               width=self.wall_width, dtype=np.int32)))
        self._release()  # the block is on the device now
        return RecordedNetwork(pairs, walls, self._match, to_device(int(g), jnp.int64),
                               tau, self.n_intervals)

    def block_intervals(self) -> int:
        """Intervals per device call of :meth:`replay`: as many as fit in
        :data:`REPLAY_BLOCK_BYTES` (at least one)."""
        row = self.pair_width * (4 + 4 + 8) + self.wall_width * (4 + 8 + 4)
        return max(1, REPLAY_BLOCK_BYTES // row)

    def replay(self, model, T, Q, g, n_steps: int):
        """:meth:`RecordedNetwork.advance` over ``n_steps`` intervals from the counter ``g``:
        on the whole cycle (:attr:`net`, put on the device once) if it fits in
        :data:`REPLAY_BLOCK_BYTES`, else with the networks put on the device a block of
        :meth:`block_intervals` at a time (``g`` is then read on the host once)."""
        block = self.block_intervals()
        if self.n_intervals <= block:  # a small bed: no padding on the host per chunk
            return self.net.advance(model, T, Q, g, n_steps)
        g_host, done = int(g), 0
        while done < n_steps:
            k = min(block, n_steps - done)
            T, Q, g = self.networks(g_host + done, k).advance(model, T, Q, g, k)
            done += k
        return T, Q, g

    def network(self, k) -> ContactNetwork:
        """Contact network of interval ``k`` (weights = contact-time fractions)."""
        return self.net.network(k)

    def position_at(self, g: int) -> np.ndarray:
        """Positions at the start of (cyclic) interval ``g``."""
        out = np.array(self.positions[g % self.n_intervals], float)
        release_pages(self.positions)
        return out


# a Recording in a replay state is host data, not array leaves: a node without children, its
# repr part of the state's structure (checkpoints compare it)
jax.tree_util.register_static(Recording)


class RecordedNetwork(eqx.Module):
    """Recorded networks on the device: rows of padded per-interval networks and the restart
    assignment, with the replay step (a PyTree).

    pairs: (i, j, weight) arrays (R, P); walls: (particle, weight, wall id) arrays (R, W);
    match: (N,) restart assignment; g0: the cyclic interval counter of row 0 (the rows are the
    intervals ``g0, g0 + 1, ...`` modulo K, R of them); tau: recording interval, s;
    n_intervals: K, the cycle's intervals.
    """

    pairs: tuple
    walls: tuple
    match: jax.Array
    g0: jax.Array
    tau: float = eqx.field(static=True)
    n_intervals: int = eqx.field(static=True)

    def network(self, k) -> ContactNetwork:
        """Contact network of row ``k`` (weights = contact-time fractions)."""
        i, j, w = (a[k] for a in self.pairs)
        wp, ww, wid = (a[k] for a in self.walls)
        return ContactNetwork(i, j, w, wp, wid, ww)

    def advance(self, model, T, Q, g, n_steps: int):
        """``n_steps`` explicit steps of one recording interval each from the cyclic interval
        counter ``g`` (rows ``g - g0`` on, modulo R): ``(T, Q, g)`` after them. A step whose
        counter is a positive multiple of K first carries the temperatures over to the restart
        positions (:func:`restart_assignment`)."""
        return _replay_steps(self, model, T, Q, g, int(n_steps))


@eqx.filter_jit
def _replay_steps(net: RecordedNetwork, model, T, Q, g, n_steps):
    C = model.particles.capacity
    K, tau, rows = net.n_intervals, net.tau, net.pairs[0].shape[0]

    def step(carry, _):
        T, Q, g = carry
        T = jnp.where((g % K == 0) & (g > 0), T[net.match], T)
        q, ext = model.heat_flows(T, net.network((g - net.g0) % rows))
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
            capacity=model.particles.host_capacity(), group=self.group,
            n_contacts=np.full(n_out, rec.mean_pairs), n_wall_contacts=np.full(n_out, rec.mean_wall),
            wall_area=np.full(n_out, d2 * rec.mean_wall))

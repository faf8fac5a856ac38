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

from pathlib import Path

import jax
import jax.numpy as jnp
import numpy as np

from drumheat.assemble import group_index, output_times
from drumheat.motion.static import StaticBed
from drumheat.runner.progress import SimProgress
from drumheat.scene import Scene, SceneError
from drumheat.thermal.network import ContactNetwork
from drumheat.motion.trajectory import Trajectory


def _pad_csr(ptr, cols, fill, dtype):
    k = len(ptr) - 1
    width = max(1, int(np.max(np.diff(ptr))) if k else 1)
    out = [np.full((k, width), f, dtype) for f in fill]
    for r in range(k):
        a, b = ptr[r], ptr[r + 1]
        for o, c in zip(out, cols):
            o[r, : b - a] = c[a:b]
    return out


def restart_assignment(end_pos, start_pos, group) -> np.ndarray:
    """Particle whose temperature each particle takes at a cyclic restart.

    ``match[b] = a``: particle b, back at its recorded start position, takes the temperature of
    particle a of the same group whose end position is closest (optimal assignment of squared
    distances, scipy's ``linear_sum_assignment``, per group).
    """
    from scipy.optimize import linear_sum_assignment

    match = np.arange(len(group))
    for g in np.unique(group):
        idx = np.nonzero(group == g)[0]
        cost = np.sum((start_pos[idx, None, :] - end_pos[None, idx, :]) ** 2, axis=-1)
        rows, cols = linear_sum_assignment(cost)
        match[idx[rows]] = idx[cols]
    return match


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
        i, j, w = _pad_csr(rec["pair_ptr"], (rec["pair_i"], rec["pair_j"],
                                             rec["pair_duration"] / self.tau), (0, 0, 0.0), None)
        heated = np.asarray(rec["wall_heated"], float)[rec["wall_index"]]
        # wall id of each contact (drums with internals book each surface separately)
        ids = (np.asarray(rec["wall_ids"], np.int32)[rec["wall_index"]] if "wall_ids" in rec
               else np.zeros(len(rec["wall_index"]), np.int32))
        wp, ww, wid = _pad_csr(rec["wall_ptr"], (rec["wall_particle"],
                                                 rec["wall_duration"] / self.tau * heated, ids),
                               (0, 0.0, 0), None)
        self.pairs = (jnp.asarray(i, jnp.int32), jnp.asarray(j, jnp.int32), jnp.asarray(w, float))
        self.walls = (jnp.asarray(wp, jnp.int32), jnp.asarray(ww, float),
                      jnp.asarray(wid, jnp.int32))
        self.positions = np.asarray(rec["positions"], float)
        self.span = self.tau * self.n_intervals
        self.mean_pairs = float(np.sum(rec["pair_duration"])) / self.span
        self.mean_wall = float(np.sum(rec["wall_duration"] * heated)) / self.span
        self.match = restart_assignment(self.positions[-1], self.positions[0],
                                        np.asarray(rec["group"]))

    def network(self, k) -> ContactNetwork:
        """Contact network of interval ``k`` (weights = contact-time fractions)."""
        i, j, w = (a[k] for a in self.pairs)
        wp, ww, wid = (a[k] for a in self.walls)
        return ContactNetwork(i, j, w, wp, wid, ww)

    def integrate(self, model, T0, Q0, g0: int, steps_per_output: int, n_outputs: int,
                  progress: SimProgress | None = None, t0: float = 0.0):
        """Explicit steps of one recording interval each, cyclically from interval ``g0``.

        Returns the states ``(T, Q)`` at the ``n_outputs`` output times after the start
        (``steps_per_output`` intervals apart) and the interval counter at the end. A step whose
        counter is a positive multiple of the number of intervals first carries the
        temperatures over to the restart positions (:func:`restart_assignment`).
        """
        K, tau = self.n_intervals, self.tau
        match = jnp.asarray(self.match)
        C = model.particles.capacity

        def step(carry, _):
            T, Q, g = carry
            k = g % K
            T = jnp.where((k == 0) & (g > 0), T[match], T)
            q, ext = model.heat_flows(T, self.network(k))
            return (T + tau * q / C, {a: Q[a] + tau * ext[a] for a in Q}, g + 1), None

        advance = jax.jit(lambda c: jax.lax.scan(step, c, None, length=steps_per_output)[0])
        carry = (jnp.asarray(T0, float), Q0, jnp.asarray(g0, jnp.int64))
        Ts, Qs = [], []
        for m in range(n_outputs):
            carry = advance(carry)
            Ts.append(carry[0])
            Qs.append(carry[1])
            if progress is not None:
                progress.update_to(t0 + (m + 1) * steps_per_output * tau)
        return Ts, Qs, int(carry[2])

    def position_at(self, g: int) -> np.ndarray:
        """Positions at the start of (cyclic) interval ``g``."""
        return self.positions[g % self.n_intervals]


class ReplayBed(StaticBed):
    """Thermal-only replay of a recorded contact network (see the module docstring)."""

    supports_particle_sharding = False

    def __init__(self, scene: Scene):
        self.scene = scene
        path = Path(scene.replay.file)
        if not path.is_absolute() and scene.source_path:
            path = Path(scene.source_path).parent / path
        if not path.exists():
            raise SceneError("replay.file", scene.replay.file, "no such recording (write one "
                             "with a 'dem' run and dem.record_interval)", scene.name)
        with np.load(path) as f:
            raw = {k: f[k] for k in f.files}
        self.group = group_index(scene)
        n = len(self.group)
        if int(raw["n_particles"]) != n:
            raise SceneError("replay.file", scene.replay.file, f"holds {int(raw['n_particles'])}"
                             f" particles; the scene has {n}", scene.name)
        raw["group"] = self.group
        self.rec = rec = Recording(raw)
        self.diameter = raw["diameter"]
        self.t_out = output_times(scene)
        self.steps_per_output = int(round(scene.run.output_interval / rec.tau))
        if abs(self.steps_per_output * rec.tau - scene.run.output_interval) > 1e-9 * rec.tau:
            raise SceneError("run.output_interval", scene.run.output_interval,
                             f"must be a multiple of the recording interval {rec.tau:g} s",
                             scene.name)
        if len(self.t_out) > 1 and abs(self.t_out[-1] - self.t_out[-2]
                                       - scene.run.output_interval) > 1e-9:
            raise SceneError("run.duration", scene.run.duration, "must be a multiple of "
                             "run.output_interval for a replay", scene.name)
        if scene.run.duration > rec.span * (1 + 1e-12) and not scene.replay.cyclic:
            raise SceneError("run.duration", scene.run.duration, f"exceeds the recording "
                             f"({rec.span:g} s); set replay.cyclic = true or shorten the run",
                             scene.name)

    def solve(self, params=None, progress: SimProgress | None = None):
        """Temperatures ``(n_out, N)`` and exchanged heat ``{account: (n_out,)}``;
        differentiable with respect to ``params``."""
        model, T0 = self.model(params)
        Q0 = {a: jnp.zeros(()) for a in model.accounts}
        Ts, Qs, _ = self.rec.integrate(model, T0, Q0, 0, self.steps_per_output,
                                       len(self.t_out) - 1, progress)
        Ts, Qs = [jnp.asarray(T0, float)] + Ts, [Q0] + Qs
        return jnp.stack(Ts), {a: jnp.stack([q[a] for q in Qs]) for a in model.accounts}

    def trajectory(self, params=None, progress: bool | None = True) -> Trajectory:
        model, _ = self.model(params)
        with SimProgress(self.scene.run.duration, progress) as bar:
            T, Q = self.solve(params, bar)
        n_out = len(self.t_out)
        rec = self.rec
        d2 = float(np.mean(self.diameter**2))
        return Trajectory(
            t=self.t_out, T=np.asarray(T), Q={k: np.asarray(v) for k, v in Q.items()},
            position=np.stack([rec.position_at(m * self.steps_per_output) for m in range(n_out)]),
            diameter=self.diameter, mass=np.asarray(model.particles.mass),
            capacity=np.asarray(model.particles.capacity), group=self.group,
            n_contacts=np.full(n_out, rec.mean_pairs), n_wall_contacts=np.full(n_out, rec.mean_wall),
            wall_area=np.full(n_out, d2 * rec.mean_wall))

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

from drumheat.bed import group_index, output_times
from drumheat.mixing.static import StaticBed
from drumheat.progress import SimProgress
from drumheat.scene import Scene, SceneError
from drumheat.thermal.network import ContactNetwork
from drumheat.trajectory import Trajectory


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


class ReplayBed(StaticBed):
    """Thermal-only replay of a recorded contact network (see the module docstring)."""

    def __init__(self, scene: Scene):
        self.scene = scene
        path = Path(scene.replay.file)
        if not path.is_absolute() and scene.source_path:
            path = Path(scene.source_path).parent / path
        if not path.exists():
            raise SceneError("replay.file", scene.replay.file, "no such recording (write one "
                             "with a 'dem' run and dem.record_interval)", scene.name)
        with np.load(path) as f:
            rec = {k: f[k] for k in f.files}
        self.group = group_index(scene)
        n = len(self.group)
        if int(rec["n_particles"]) != n:
            raise SceneError("replay.file", scene.replay.file, f"holds {int(rec['n_particles'])}"
                             f" particles; the scene has {n}", scene.name)
        self.tau = float(rec["interval"])
        self.n_intervals = len(rec["pair_ptr"]) - 1
        span = self.tau * self.n_intervals
        self.t_out = output_times(scene)
        self.steps_per_output = int(round(scene.run.output_interval / self.tau))
        if abs(self.steps_per_output * self.tau - scene.run.output_interval) > 1e-9 * self.tau:
            raise SceneError("run.output_interval", scene.run.output_interval,
                             f"must be a multiple of the recording interval {self.tau:g} s",
                             scene.name)
        if len(self.t_out) > 1 and abs(self.t_out[-1] - self.t_out[-2]
                                       - scene.run.output_interval) > 1e-9:
            raise SceneError("run.duration", scene.run.duration, "must be a multiple of "
                             "run.output_interval for a replay", scene.name)
        if scene.run.duration > span * (1 + 1e-12) and not scene.replay.cyclic:
            raise SceneError("run.duration", scene.run.duration, f"exceeds the recording "
                             f"({span:g} s); set replay.cyclic = true or shorten the run",
                             scene.name)
        i, j, w = _pad_csr(rec["pair_ptr"], (rec["pair_i"], rec["pair_j"],
                                             rec["pair_duration"] / self.tau), (0, 0, 0.0), None)
        heated = rec["wall_heated"].astype(float)[rec["wall_index"]]
        wp, ww = _pad_csr(rec["wall_ptr"], (rec["wall_particle"],
                                            rec["wall_duration"] / self.tau * heated), (0, 0.0),
                          None)
        self.pairs = (jnp.asarray(i, jnp.int32), jnp.asarray(j, jnp.int32), jnp.asarray(w, float))
        self.walls = (jnp.asarray(wp, jnp.int32), jnp.asarray(ww, float))
        self.positions = rec["positions"].astype(float)
        self.diameter = rec["diameter"]
        self.match = restart_assignment(self.positions[-1], self.positions[0], self.group)
        self.mean_pairs = float(np.sum(rec["pair_duration"])) / span
        self.mean_wall = float(np.sum(rec["wall_duration"] * heated)) / span if heated.size \
            else 0.0
        self.recording = rec

    def _interval_network(self, k) -> ContactNetwork:
        i, j, w = (a[k] for a in self.pairs)
        wp, ww = (a[k] for a in self.walls)
        return ContactNetwork(i, j, w, wp, jnp.zeros_like(wp), ww)

    def solve(self, params=None, progress: SimProgress | None = None):
        """Temperatures ``(n_out, N)`` and exchanged heat ``{account: (n_out,)}``;
        differentiable with respect to ``params``."""
        model, T0 = self.model(params)
        K, tau = self.n_intervals, self.tau
        match = jnp.asarray(self.match)
        C = model.particles.capacity

        def step(carry, _):
            T, Q, g = carry
            k = g % K
            T = jnp.where((k == 0) & (g > 0), T[match], T)
            q, ext = model.heat_flows(T, self._interval_network(k))
            T = T + tau * q / C
            Q = {a: Q[a] + tau * ext[a] for a in Q}
            return (T, Q, g + 1), None

        @jax.jit
        def advance(carry):
            return jax.lax.scan(step, carry, None, length=self.steps_per_output)[0]

        carry = (jnp.asarray(T0, float), {a: jnp.zeros(()) for a in model.accounts},
                 jnp.asarray(0, jnp.int64))
        Ts, Qs = [carry[0]], [carry[1]]
        for t_end in self.t_out[1:]:
            carry = advance(carry)
            Ts.append(carry[0])
            Qs.append(carry[1])
            if progress is not None:
                progress.update_to(t_end)
        return jnp.stack(Ts), {a: jnp.stack([q[a] for q in Qs]) for a in model.accounts}

    def trajectory(self, params=None, progress: bool | None = True) -> Trajectory:
        model, _ = self.model(params)
        with SimProgress(self.scene.run.duration, progress) as bar:
            T, Q = self.solve(params, bar)
        n_out = len(self.t_out)
        steps = np.arange(n_out) * self.steps_per_output % self.n_intervals
        d2 = float(np.mean(self.diameter**2))
        return Trajectory(
            t=self.t_out, T=np.asarray(T), Q={k: np.asarray(v) for k, v in Q.items()},
            position=self.positions[steps], diameter=self.diameter,
            mass=np.asarray(model.particles.mass), capacity=np.asarray(model.particles.capacity),
            group=self.group, n_contacts=np.full(n_out, self.mean_pairs),
            n_wall_contacts=np.full(n_out, self.mean_wall),
            wall_area=np.full(n_out, d2 * self.mean_wall))

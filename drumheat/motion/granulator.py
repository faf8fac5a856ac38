"""Motion model ``granulator``: one slag droplet through the three phases of a dry granulator.

staltner-slag-particle.md sections 1-8. The droplet (one particle with radial shells,
``[heat.internal]``) leaves the centre of the spinning disc at the speed ``v_S = 0.8 pi d_Dt
n_Dt`` [4.1] and

1. **flies** horizontally to the water-cooled cone (Phase 1, ``t_1 = s_1 / v_S``): convection to
   the freeboard air (``[heat.convection]``, fluid temperature ``gas.temperature`` = T_FB) and
   radiation to the four-zone enclosure (``[heat.radiation]``, enclosure 'granulator'); the
   view factors follow the droplet: the path is cut into ``granulator.segments`` pieces and the
   radiation sink temperature T_rad is taken at each piece's midpoint (section 7.1 exact solid
   angles, section 4 T_rad);
2. **rests on the wall** (Phase 2): convection and radiation off, the surface node held at the
   contact temperature of two semi-infinite bodies ``T_m = T_4 + b_S/(b_S + b_W)(T_s^0 - T_4)``
   ([3.10]-[3.11], [5.29]-[5.32]; b_S at the surface temperature when contact begins;
   ``granulator.contact_mode`` "surface": node n held at T_m, the digest's consistent reading;
   "ghost": T_m one cell outside the sphere, the thesis' literal reading, see
   :class:`GhostContact`), until the droplet's mean enthalpy has fallen by
   ``Q_W / m_S`` ([4.8], [4.9]: enthalpy-matched contact time; the crossing is found step by step
   and interpolated linearly between the two steps around it);
3. **falls** to the bed (Phase 3, ``t_3 = s_3 / v_S``), as Phase 1.

Paths (digest note in section 1, a reconstruction): the disc sits at ``z_D = h3 + h4/2`` unless
``granulator.disc_height`` says otherwise; the droplet hits the cone at radius ``r_w = r2 - (z_D -
h3)/tan(alpha4)`` (``s_1 = r_w``), is reflected specularly and falls at the angle ``2 alpha4``
below the outward horizontal (``s_3 = z_D / sin(2 alpha4)``). Sub-phase 3* (inside the conical
freeboard) is the fraction ``(z_D - h3)/z_D`` of Phase 3.

Not modelled here (left to a freeboard model): the coupled balances [7.7]-[7.18] that make the
zone temperatures T_2 = T_3 = T_WS, T_5 = T_L,aus and the fluid temperature T_FB outputs of a
fixed-point iteration over all size classes. This motion model takes them as scene inputs
(``[[heat.radiation.surfaces]]``, ``gas.temperature``).

Results beyond the standard files: ``phases.csv`` (phase, duration, mean temperatures after it,
surface and centre temperature, heat by account), ``radial_profiles.png`` (the radial profile at
times through the run, one panel per phase) and ``profiles.npz`` (t, r, T of every recorded step).
"""

from __future__ import annotations

import math

import equinox as eqx
import jax
import jax.numpy as jnp
import numpy as np

from drumheat import assemble
from drumheat.models.granulator import droplet_speed, path_geometry, wall_heat_per_mass
from drumheat.models.sphere_conduction import (contact_temperature, effusivity,
                                               ghost_node_contact_flux)
from drumheat.motion.base import AbstractMotion, register
from drumheat.motion.trajectory import Trajectory
from drumheat.scene import Scene, SceneError
from drumheat.thermal import internal, shells
from drumheat.thermal.effect import TableValues
from drumheat.thermal.network import ContactNetwork
from drumheat.thermal.radiation import granulator_sink_temperature

PHASES = ("flight", "wall contact", "fall")


class GhostContact(eqx.Module):
    """Phase-2 boundary with the contact temperature one cell outside the sphere (issue 20).

    ``granulator.contact_mode = "ghost"``: the thesis stores T_m in node n+1 and updates the
    surface node with the interior stencil ([5.31]-[5.32], staltner-slag-particle.md section 3,
    digest note). The explicit scheme takes this literally
    (``shells.FixedSurfaceTemperature(mode="ghost")``); the implicit finite-volume scheme gets the
    same east-face heat flow as a surface flux,
    :func:`drumheat.models.sphere_conduction.ghost_node_contact_flux` (``q_out(T_s)``, the form
    every shell boundary with a ``flux`` method has).
    """

    T_m: jax.Array  # (N,) K
    radius: jax.Array  # (N,) m
    dr: jax.Array  # (N,) m
    material: eqx.Module

    def flux(self, Ts):
        return ghost_node_contact_flux(Ts, self.T_m, self.material.conductivity(Ts),
                                       self.material.conductivity(self.T_m), self.radius, self.dr)


@eqx.filter_jit
def _effect_scan(model, net, T, h, n: int, scheme: str):
    step = internal.implicit_step if scheme == "implicit" else internal.explicit_step

    def body(T, _):
        T2, dQ = step(model, net, T, h)
        return T2, (T2, dQ)

    _, (Ts, dQ) = jax.lax.scan(body, T, None, length=n)
    return Ts, dQ


@eqx.filter_jit
def _contact_scan(T, h, n: int, grid, material, boundary, scheme: str):
    def body(T, _):
        if scheme == "implicit":
            T2, _ = shells.implicit_step(T, h, grid, material, boundary)
        else:
            T2, _ = shells.explicit_step(T, h, grid, material, boundary, check=True)
        return T2, T2

    _, Ts = jax.lax.scan(body, T, None, length=n)
    return Ts


@register
class GranulatorParticle(AbstractMotion):
    """One droplet through flight, wall contact and fall (module docstring).

    Not vmappable and not differentiable: the end of Phase 2 is found on the host (the
    enthalpy-matched contact time, staltner [4.9]) and the output times follow the phase
    ends, so the run is one host-driven chunk from 0 to ``run.duration`` (an upper bound; the
    phases end the run). The phase table travels in the trajectory's ``info["phases"]``.
    """

    name = "granulator"

    def __init__(self, scene: Scene):
        super().__init__(scene)
        self.times = np.array([0.0, float(scene.run.duration)])
        self.g = scene.granulator
        self.path = path_geometry(self.g)
        self.v_S = droplet_speed(self.g)
        self.net = ContactNetwork.from_arrays(np.zeros((0, 2)), np.zeros(0))

    # -- building blocks ----------------------------------------------------------------
    def model(self, params=None):
        """Thermal model and initial temperature: convection at the droplet speed [4.1],
        radiation to the enclosure seen from the disc (updated along the paths)."""
        g = TableValues(self.scene.granulator, "granulator", params)
        sink = None
        rad = self.scene.heat.radiation
        if rad is not None and rad.enclosure == "granulator":
            value = assemble.scene_values(self.scene, params)
            eps = (rad.emissivity if rad.emissivity is not None
                   else float(assemble.group_property(self.scene, value, 0, "emissivity")))
            sink = granulator_sink_temperature(0.0, self.path["z_disc"], self.g, rad.surfaces,
                                               float(eps))
        return assemble.thermal_model(self.scene, params, gas_velocity=droplet_speed(g),
                                      sink_temperature=sink)

    def initial_state(self, params=None):
        model, T0 = self.model(params)
        return {"model": model, "T0": T0, "record": None}

    def advance(self, state, t0, t1):
        """All three phases (module docstring), whatever ``t1``."""
        return dict(state, record=self._run(state["model"], state["T0"]))

    def observe(self, state) -> dict:
        return {}  # the record of the phases holds every step

    def _positions(self, phase: int, frac):
        """(rho, z) along the Phase-1 or Phase-3 path at path fractions ``frac``."""
        p, frac = self.path, np.asarray(frac, float)
        if phase == 1:
            return frac * p["r_wall"], np.full_like(frac, p["z_disc"])
        return (p["r_wall"] + frac * (p["rho_land"] - p["r_wall"]),
                p["z_disc"] * (1.0 - frac))

    def _sink_temperatures(self, phase: int, model):
        K = self.g.segments
        rho, z = self._positions(phase, (np.arange(K) + 0.5) / K)
        rad = model.effect("radiation")
        if rad is None or self.scene.heat.radiation.enclosure != "granulator":
            return None
        eps = float(rad.emissivity[0])
        return np.asarray(granulator_sink_temperature(rho, z, self.g,
                                                      self.scene.heat.radiation.surfaces, eps))

    def _step_size(self, model, T, duration):
        """Shell step and scheme of a flight phase: ``heat.internal.dt`` or the phase in
        ``granulator.steps_per_phase`` steps, the explicit limit checked at the phase's start
        (:func:`drumheat.thermal.internal.plan_step`)."""
        try:
            scheme, dt = internal.plan_step(model, self.net, T, duration,
                                            default_dt=duration / self.g.steps_per_phase)
        except internal.ShellStepError as err:
            raise SceneError("heat.internal.dt", model.internal.dt, f"{err} (at the start of a "
                             "granulator phase; or use heat.internal.on_unstable = "
                             "'implicit')", self.scene.name) from None
        return dt, scheme

    # -- the run --------------------------------------------------------------------------
    def _run(self, model, T0):
        it = model.internal
        grid, mat = it.grid, it.material
        accounts = tuple(sorted(set(model.accounts) | {"wall"}))
        T = it.initial(T0)
        rec_t, rec_T, rec_phase = [0.0], [np.asarray(T)], [1]
        Q = {a: 0.0 for a in accounts}
        rec_Q = [dict(Q)]
        rec_Trad = [np.nan]
        t = 0.0
        table = []
        H = lambda T: float(jnp.sum(it.stored_heat(T)))
        mass = float(jnp.sum(model.particles.mass))
        V = float(jnp.sum(grid.volume))

        def record_phase(k, t_start, T_end):
            Tm = float(it.mean_temperature(T_end)[0])
            table.append(dict(phase=k, name=PHASES[k - 1], t_start_s=t_start,
                              duration_s=t - t_start, t_end_s=t, T_mean_K=Tm,
                              T_mean_degC=Tm - 273.15,
                              T_volume_mean_K=float(it.volume_mean_temperature(T_end)[0]),
                              T_surface_K=float(T_end[0, -1]), T_centre_K=float(T_end[0, 0]),
                              **{f"Q_{a}_J": Q[a] for a in accounts}))

        for phase in (1, 2, 3):
            t_start = t
            if phase in (1, 3):
                s = self.path["s1"] if phase == 1 else self.path["s3"]
                duration = s / self.v_S
                K = self.g.segments
                dt, scheme = self._step_size(model, T, duration)
                n_seg = max(1, math.ceil(duration / K / dt - 1e-9))
                h = duration / K / n_seg
                T_rad = self._sink_temperatures(phase, model)
                for k in range(K):
                    m = model
                    if T_rad is not None:
                        m = eqx.tree_at(lambda mm: mm.effect("radiation").sink_temperature,
                                        model, jnp.full(1, T_rad[k]))
                    Ts, dQ = _effect_scan(m, self.net, T, jnp.asarray(h), n_seg, scheme)
                    Ts = np.asarray(Ts)
                    dQ = {a: np.cumsum(np.asarray(v)) for a, v in dQ.items()}
                    for j in range(n_seg):
                        rec_t.append(t + (j + 1) * h)
                        rec_T.append(Ts[j])
                        rec_phase.append(phase)
                        rec_Q.append({a: Q[a] + (dQ[a][j] if a in dQ else 0.0) for a in accounts})
                        rec_Trad.append(np.nan if T_rad is None else T_rad[k])
                    for a in dQ:
                        Q[a] += float(dQ[a][-1])
                    T = jnp.asarray(Ts[-1])
                    t += n_seg * h
            else:
                T, t = self._contact_phase(model, T, t, Q, accounts, rec_t, rec_T, rec_phase,
                                           rec_Q, rec_Trad, H)
            record_phase(phase, t_start, T)
        rec = dict(t=np.asarray(rec_t), T=np.stack(rec_T), phase=np.asarray(rec_phase),
                   Q={a: np.asarray([q[a] for q in rec_Q]) for a in accounts},
                   T_rad=np.asarray(rec_Trad), model=model, mass=mass, volume=V, phases=table,
                   contact_temperature=self._T_m)
        return rec

    def _contact_phase(self, model, T, t, Q, accounts, rec_t, rec_T, rec_phase, rec_Q,
                       rec_Trad, H):
        g, it = self.g, model.internal
        grid, mat = it.grid, it.material
        Ts0 = T[:, -1]
        rho = float(shells._col(mat.density, T).reshape(-1)[0])
        b_S = effusivity(mat.conductivity(Ts0), mat.heat_capacity(Ts0), rho)
        b_W = effusivity(g.wall_conductivity, g.wall_heat_capacity, g.wall_density)
        T_m = contact_temperature(Ts0, b_S, g.wall_temperature, b_W)
        self._T_m = float(T_m[0])
        dh = wall_heat_per_mass(g)
        mV = float(jnp.sum(shells._col(mat.density, T) * grid.volume))
        H_start = H(T)
        H_target = H_start - dh * mV
        H_floor = float(jnp.sum(it.stored_heat(jnp.broadcast_to(T_m[:, None], T.shape))))
        if H_target <= H_floor:
            raise SceneError("granulator.slag_rate", g.slag_rate,
                             f"the wall cannot take Q_W/m_S = {dh:.4g} J/kg from the droplet: "
                             "even cooled to the contact temperature "
                             f"{float(T_m[0]):.1f} K it holds less (staltner section 8, [4.9])",
                             self.scene.name)
        # time estimate: two semi-infinite bodies (weigler [1.12] form), for the step size
        b_eff = float(b_S[0] * b_W / (b_S[0] + b_W))
        R = float(grid.radius[0])
        t_est = math.pi * (dh * rho * R / 3.0 / (2.0 * b_eff * float(Ts0[0] - g.wall_temperature))) ** 2
        dt = it.dt if it.dt is not None else t_est / g.steps_per_phase
        scheme = it.scheme
        # granulator.contact_mode (issue 20): "surface" holds node n at T_m; "ghost" puts T_m
        # one cell outside (explicit: the thesis stencil [5.32]; implicit: the same face flux)
        def contact_boundary(scheme):
            if g.contact_mode == "surface":
                return shells.FixedSurfaceTemperature(T_m, mode="surface")
            if scheme == "explicit":
                return shells.FixedSurfaceTemperature(T_m, mode="ghost")
            return GhostContact(T_m, grid.radius, grid.dr, mat)

        boundary = contact_boundary(scheme)
        if scheme == "explicit":
            lim = float(jnp.min(shells.explicit_stability_limit(T, grid, mat, boundary)))
            if dt > lim:
                if it.on_unstable == "refuse":
                    raise SceneError("heat.internal.dt", it.dt,
                                     f"explicit shell step dt = {dt:.4g} s exceeds the Phase-2 "
                                     f"stability limit {lim:.4g} s ([A.2], [A.4])", self.scene.name)
                scheme = "implicit"
                boundary = contact_boundary(scheme)
        n = 2 * g.steps_per_phase
        for _ in range(200):
            Ts = np.asarray(_contact_scan(T, jnp.asarray(dt), n, grid, mat, boundary, scheme))
            Hs = np.asarray(jax.vmap(lambda x: jnp.sum(it.stored_heat(x)))(jnp.asarray(Ts)))
            H_prev = np.concatenate([[H(T)], Hs[:-1]])
            hit = np.nonzero(Hs <= H_target)[0]
            k_end = hit[0] if len(hit) else n - 1
            H_now = H(T)
            for j in range(k_end + 1):
                if len(hit) and j == k_end:
                    f = (H_prev[j] - H_target) / (H_prev[j] - Hs[j])
                    T_prev = np.asarray(T) if j == 0 else Ts[j - 1]
                    T_end = T_prev + f * (Ts[j] - T_prev)
                    t_j = t + (j + f) * dt
                    H_j = H_target
                else:
                    T_end, t_j, H_j = Ts[j], t + (j + 1) * dt, Hs[j]
                rec_t.append(t_j)
                rec_T.append(T_end)
                rec_phase.append(2)
                rec_Q.append({a: Q[a] + (H_j - H_start if a == "wall" else 0.0) for a in accounts})
                rec_Trad.append(np.nan)
            if len(hit):
                Q["wall"] += H_target - H_start
                return jnp.asarray(rec_T[-1]), rec_t[-1]
            T = jnp.asarray(Ts[-1])
            t += n * dt
        raise SceneError("granulator.slag_rate", g.slag_rate, "no enthalpy crossing found in "
                         "Phase 2 within 200 chunks; check the inputs", self.scene.name)

    # -- the result -------------------------------------------------------------------------
    def finish(self, rows, log, state) -> Trajectory:
        rec = state["record"]
        model, it = rec["model"], rec["model"].internal
        phases = rec["phases"]
        keep = self._output_indices(rec["t"], rec["phase"])
        t = rec["t"][keep]
        prof = rec["T"][keep]
        T = np.asarray(it.mean_temperature(jnp.asarray(prof)))
        H = np.asarray(jax.vmap(lambda x: jnp.sum(it.stored_heat(x)))(jnp.asarray(prof)))
        pos = np.zeros((len(t), 1, 3))
        frac = np.zeros(len(t))
        for ph in (1, 3):
            m = rec["phase"][keep] == ph
            row = phases[ph - 1]
            frac[m] = (t[m] - row["t_start_s"]) / row["duration_s"]
            rho, z = self._positions(ph, frac[m])
            pos[m, 0, 0], pos[m, 0, 1] = rho, z
        m2 = rec["phase"][keep] == 2
        pos[m2, 0, 0], pos[m2, 0, 1] = self.path["r_wall"], self.path["z_disc"]
        d = np.asarray(model.particles.diameter)
        extra = {"phase": rec["phase"][keep].astype(float),
                 "T_surface": prof[:, 0, -1], "T_centre": prof[:, 0, 0],
                 "T_volume_mean": np.asarray(it.volume_mean_temperature(jnp.asarray(prof)))[:, 0],
                 "T_rad": rec["T_rad"][keep]}
        r = np.asarray(it.grid.r[0])
        all_t, all_T = rec["t"], rec["T"][:, 0, :]
        files = {"phases.csv": lambda p: _write_phases(p, phases),
                 "profiles.npz": lambda p: np.savez_compressed(p, t=all_t, r=r, T=all_T,
                                                               phase=rec["phase"]),
                 "radial_profiles.png": lambda p: plot_radial_profiles(
                     p, all_t, r, all_T, rec["phase"], phases, self.scene)}
        n_out = len(t)
        return Trajectory(
            t=t, T=T, Q={a: v[keep] for a, v in rec["Q"].items()}, position=pos, diameter=d,
            mass=np.asarray(model.particles.mass), capacity=model.particles.host_capacity(),
            group=assemble.group_index(self.scene), n_contacts=np.zeros(n_out),
            n_wall_contacts=m2.astype(float), wall_area=np.zeros(n_out), extra=extra,
            stored_heat=H - H[0], files=files,
            info={"phases": phases, "contact_temperature_K": rec["contact_temperature"]},
            records={"t": all_t, "T": rec["T"], "phase": rec["phase"], "Q": rec["Q"]})

    def _output_indices(self, t, phase):
        """Recorded steps kept as outputs: one per output interval plus every phase end."""
        dt_out = self.scene.run.output_interval
        slot = np.floor(t / dt_out + 1e-9)
        keep = {0, len(t) - 1}
        keep |= set(np.nonzero(np.diff(slot) > 0)[0] + 1)
        keep |= set(np.nonzero(np.diff(phase) != 0)[0])  # last step of each phase
        return np.array(sorted(keep))


def _write_phases(path, phases):
    import pandas as pd

    pd.DataFrame(phases).to_csv(path, index=False, float_format="%.8g")


def plot_radial_profiles(path, t, r, T, phase, phases, scene, n_curves=6):
    """Radial temperature profiles over time, one panel per phase (staltner Figs. 8.2-8.25 style)."""
    import matplotlib

    matplotlib.use("Agg", force=False)
    import matplotlib.pyplot as plt

    fig, axes = plt.subplots(1, 3, figsize=(13, 4.2), sharey=True)
    R = r[-1]
    for ax, row in zip(axes, phases):
        idx = np.nonzero(phase == row["phase"])[0]
        if row["phase"] > 1:
            idx = np.concatenate([[idx[0] - 1], idx])
        elif True:
            idx = np.concatenate([[0], idx])
        pick = idx[np.unique(np.linspace(0, len(idx) - 1, n_curves).round().astype(int))]
        cmap = plt.get_cmap("viridis")
        for k, i in enumerate(pick):
            ax.plot(r / R, T[i] - 273.15, color=cmap(k / max(1, len(pick) - 1)),
                    label=f"t = {1e3 * t[i]:.2f} ms")
        for theta, lab in ((991.0, "softening 991 °C"), (1262.0, "flow 1262 °C")):
            ax.axhline(theta, color="0.6", lw=0.8, ls="--")
        ax.set_title(f"Phase {row['phase']}: {row['name']} ({1e3 * row['duration_s']:.2f} ms)")
        ax.set_xlabel("r / R")
        ax.grid(alpha=0.3)
        ax.legend(fontsize="x-small")
    axes[0].set_ylabel("temperature / °C")
    d = float(scene.groups[0].diameter)
    fig.suptitle(f"{scene.name}: slag droplet d = {1e3 * d:g} mm, radial profiles "
                 f"(dashed: softening and flow temperature)")
    fig.tight_layout()
    fig.savefig(path, dpi=120)
    plt.close(fig)

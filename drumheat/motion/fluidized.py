"""Motion model ``fluidized``: a batch fluidised bed with gas in plug flow.

fluidized-bed-exercise.md sections 1-7: the particles (beans) are fluidised by a gas that passes
the bed once in plug flow, taking up heat; the bed is well mixed. Particle-resolved here:

* every particle is simulated (lumped, or with radial shells from ``[heat.internal]``);
* the bed height is cut into ``motion.layers`` layers; the gas crosses them in turn and every
  particle exchanges heat with the gas of its layer
  (:class:`drumheat.thermal.convection.PlugFlowConvection`, the NTU form of section 4 per layer);
* fluidisation mixes the bed: every ``motion.t_R`` the particles are dealt to the layers anew
  (a random permutation from ``run.seed``, equal numbers per layer).

The simulated particles stand for the bed cross-section ``f = sum m_i / m_1`` (``motion.loading``
= m_1) through which ``gas.mass_flux * f`` of gas flows, so the result does not depend on their
number (section 1: f cancels).

The exercise's own bed-level model (section 4 closed form with ``k`` from alpha_i and alpha_a,
section 5) is evaluated alongside from the same scene values and written as the time-series
column ``T_bed_level``; the column ``T_gas_out`` is the simulated outlet gas temperature.
A scene without ``[heat.internal]`` and with ``heat.convection.internal_resistance =
"transient-sphere"`` and one layer *is* the bed-level model, integrated numerically.
"""

from __future__ import annotations

import equinox as eqx
import jax.numpy as jnp
import numpy as np

from drumheat.assemble import group_index, initial_temperatures, make_particles, output_times, scene_values
from drumheat.models import convection as corr
from drumheat.runner.progress import SimProgress
from drumheat.scene import Scene
from drumheat.thermal.composer import make_thermal_model
from drumheat.thermal.convection import PlugFlowConvection, series_with_transient_sphere
from drumheat.thermal.integrate import initial_state
from drumheat.thermal.network import ContactNetwork
from drumheat.motion.trajectory import Trajectory


@eqx.filter_jit
def _outlet(plug, Ts, particles):
    return plug.outlet_temperature(Ts, particles)


class FluidizedBed:
    """Batch fluidised bed, particle-resolved (module docstring)."""

    autodiff = "reverse"

    def __init__(self, scene: Scene):
        self.scene = scene
        self.t_out = output_times(scene)
        self.net = ContactNetwork.from_arrays(np.zeros((0, 2)), np.zeros(0))
        self.layers = scene.motion.layers
        self.t_R = scene.motion.t_R
        self._rng = np.random.default_rng([scene.run.seed, 2])

    def model(self, params=None):
        value = scene_values(self.scene, params)
        model = make_thermal_model(self.scene, make_particles(self.scene, value), value)
        return model, initial_temperatures(self.scene, value)

    def _plug(self, model):
        return [e for e in model.effects if isinstance(e, PlugFlowConvection)][0]

    def _with_layers(self, model, layer):
        return eqx.tree_at(lambda m: self._plug(m).layer, model, jnp.asarray(layer))

    def _deal(self, N):
        """Equal numbers per layer in a random order."""
        return self._rng.permutation(np.arange(N) % self.layers)

    def _grid(self):
        t_out = np.asarray(self.t_out, float)
        if self.layers == 1 or self.t_R is None:
            return t_out, np.zeros(len(t_out), bool)
        k = np.arange(1, int(np.floor(t_out[-1] / self.t_R)) + 1) * self.t_R
        k = k[k < t_out[-1] * (1 - 1e-12)]
        t = np.union1d(t_out, k)
        return t, np.isin(t, k)

    def _run(self, params=None, progress=None):
        from drumheat.motion.static import integrate_network

        model, T0 = self.model(params)
        N = model.particles.diameter.shape[0]
        layer = np.asarray(self._plug(model).layer) if self.layers == 1 else self._deal(N)
        model = self._with_layers(model, layer)
        t_grid, remix = self._grid()
        y = initial_state(model, T0)
        states, layers_at = {0.0: y}, {0.0: layer}
        if model.internal is not None:  # one step plan for the whole run
            from drumheat.scene import SceneError
            from drumheat.thermal.integrate import advance_shells
            from drumheat.thermal.internal import ShellStepError, plan_step

            try:
                scheme, dt = plan_step(model, self.net, y["T"], float(t_grid[-1] - t_grid[0]))
            except ShellStepError as err:
                raise SceneError("heat.internal.dt", self.scene.heat.internal.dt, str(err),
                                 self.scene.name) from None
            advance = lambda m, y, t0, t1: advance_shells(m, self.net, y, t0, t1, dt, scheme)
        else:
            advance = lambda m, y, t0, t1: integrate_network(self.scene, m, self.net, y,
                                                             np.array([t0, t1]))[-1]
        for t0, t1, mix in zip(t_grid[:-1], t_grid[1:], remix[1:]):
            y = advance(model, y, float(t0), float(t1))
            states[t1], layers_at[t1] = y, layer
            if progress is not None:
                progress.update_to(t1)
            if mix:
                layer = self._deal(N)
                model = self._with_layers(model, layer)
        keep = [states[float(t)] for t in self.t_out]
        return model, keep, [layers_at[float(t)] for t in self.t_out]

    def solve(self, params=None, progress=None):
        from drumheat.motion.static import stack_states

        model, states, _ = self._run(params, progress)
        return stack_states(states, model.accounts, model)

    def bed_level_model(self, params=None):
        """The exercise's bed-level cooling curve at the output times, K, and its numbers.

        fluidized-bed-exercise.md sections 4-5: ``alpha_a`` from the scene's convection (at the
        gas temperature), ``alpha_i`` from Nu_i at ``Fo(t_E)`` (t_E = run.duration),
        ``1/k = 1/alpha_i + 1/alpha_a``, ``A/f = 6 m_1/(d rho_1)``, ``NTU = k (A/f)/(mdot_2
        c_p,2)`` and the closed form ``T1(t)``. Uses the first group (equal spheres).
        """
        from drumheat.assemble import group_property
        from drumheat.materials import gas as gas_lib

        scene = self.scene
        value = scene_values(scene, params)
        model, _ = self.model(params)
        plug = self._plug(model)
        conv = plug.convection
        p = model.particles
        d = p.diameter[:1]
        rho_c = p.capacity[:1] / (jnp.pi * d**3 / 6.0)
        rho1 = p.mass[:1] / (jnp.pi * d**3 / 6.0)
        alpha = conv.alpha(jnp.full(p.diameter.shape, conv.gas_temperature), p)[:1]
        if scene.heat.convection.internal_resistance == "transient-sphere":
            k = alpha
        else:
            lam1 = jnp.asarray(group_property(scene, value, 0, "conductivity"), float)
            k = series_with_transient_sphere(alpha, d, lam1, rho_c, value("run.duration"))
        cp2 = value("gas.heat_capacity") if scene.gas.heat_capacity is not None else gas_lib(
            scene.gas.material).heat_capacity
        m1, mdot2 = value("motion.loading"), value("gas.mass_flux")
        A_f = corr.bed_area_per_cross_section(m1, d, rho1)
        ntu = corr.bed_ntu(k, A_f, mdot2, cp2)
        c1 = rho_c / rho1
        T = corr.batch_bed_mean_temperature(jnp.asarray(self.t_out), value("groups.0.temperature"),
                                            value("gas.temperature"), ntu, m1, c1, mdot2, cp2)
        info = dict(alpha_a=float(alpha[0]) if scene.heat.convection.internal_resistance == "none"
                    else None, k=float(k[0]), A_per_f=float(A_f[0]), NTU=float(ntu[0]))
        return np.asarray(T), info

    def trajectory(self, params=None, progress: bool | None = True) -> Trajectory:
        with SimProgress(self.scene.run.duration, progress) as bar:
            model, states, layers = self._run(params, bar)
        from drumheat.motion.static import shell_stored_heat, stack_states

        T, Q = stack_states(states, model.accounts, model)
        plug = self._plug(model)
        it = model.internal
        Tout = []
        for s, lay in zip(states, layers):
            Ts = s["T"] if it is None else s["T"][:, -1]
            Tout.append(float(_outlet(eqx.tree_at(lambda q: q.layer, plug, jnp.asarray(lay)),
                                      Ts, model.particles)))
        T_bed, info = self.bed_level_model(params)
        self.bed_level_info = info
        n_out, N = len(self.t_out), model.particles.diameter.shape[0]
        extra = {"T_gas_out": np.asarray(Tout), "T_bed_level": T_bed}
        if it is not None:
            prof = jnp.stack([s["T"] for s in states])
            extra["T_surface_mean"] = np.asarray(jnp.mean(prof[:, :, -1], axis=1))
            extra["T_centre_mean"] = np.asarray(jnp.mean(prof[:, :, 0], axis=1))
        # positions: height of the particle's layer in a bed at the loosening porosity
        # (H = m_1 / (rho_1 (1 - psi_L)), fluidized-bed-exercise.md section 2), x = z = 0
        rho1 = float(model.particles.mass[0] / (np.pi * model.particles.diameter[0] ** 3 / 6))
        H = self.scene.motion.loading / (rho1 * (1 - self.scene.heat.convection.loosening_porosity))
        pos = np.zeros((n_out, N, 3))
        pos[:, :, 1] = (np.stack(layers) + 0.5) / self.layers * H
        return Trajectory(
            t=self.t_out, T=np.asarray(T), Q={k: np.asarray(v) for k, v in Q.items()},
            position=pos, diameter=np.asarray(model.particles.diameter),
            mass=np.asarray(model.particles.mass), capacity=np.asarray(model.particles.capacity),
            group=group_index(self.scene), n_contacts=np.zeros(n_out),
            n_wall_contacts=np.zeros(n_out), wall_area=np.zeros(n_out), extra=extra,
            stored_heat=shell_stored_heat(model, states))

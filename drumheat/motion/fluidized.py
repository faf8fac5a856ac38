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

from drumheat import assemble
from drumheat.models import convection as corr
from drumheat.motion.base import register
from drumheat.motion.static import ThermalBed, thermal_solver
from drumheat.motion.trajectory import Trajectory
from drumheat.scene import Scene
from drumheat.thermal.convection import PlugFlowConvection, series_with_transient_sphere
from drumheat.thermal.effect import PlugFlow
from drumheat.thermal.network import ContactNetwork
from drumheat.thermal.solvers import initial_state


@eqx.filter_jit
def _outlet(plug, Ts, particles):
    return plug.outlet_temperature(Ts, particles)


@register
class FluidizedBed(ThermalBed):
    """Batch fluidised bed, particle-resolved (module docstring).

    The state is ``{"model", "y", "layer", "deals"}``: the layer of every particle and the
    layer assignments of all re-mixings of the run (drawn when the model is built, from
    ``run.seed``), so that a run is a pure function of its state.
    """

    name = "fluidized"
    vmappable = True

    def __init__(self, scene: Scene):
        super().__init__(scene)
        self.net = ContactNetwork.from_arrays(np.zeros((0, 2)), np.zeros(0))
        self.layers = scene.motion.layers
        self.t_R = scene.motion.t_R
        model, T0 = self.model()
        self.solver = thermal_solver(scene, model, self.net, T0)
        self.deals = self.deal(len(T0))

    def deal(self, N: int) -> np.ndarray:
        """The layer of every particle at the start and after each re-mixing, (k + 1, N):
        equal numbers per layer in a random order (``run.seed``, stream 2)."""
        rng = np.random.default_rng([self.scene.run.seed, 2])
        n_deals = 1 + len(self.remix_times()) if self.layers > 1 else 0
        if not n_deals:
            return np.zeros((1, N), int)
        return np.stack([rng.permutation(np.arange(N) % self.layers) for _ in range(n_deals)])

    def with_options(self, *, times=None, autodiff=None) -> "FluidizedBed":
        new = super().with_options(times=times, autodiff=autodiff)
        if times is not None:  # the re-mixings up to the new end
            new.deals = new.deal(self.deals.shape[1])
        return new

    def model(self, params=None):
        """Thermal model (convection with the gas in plug flow) and initial temperatures."""
        value = assemble.scene_values(self.scene, params)
        flow = PlugFlow(value("gas.mass_flux"), value("motion.loading"),
                        assemble.gas_state(self.scene, value).heat_capacity, self.scene.motion.layers)
        return assemble.thermal_model(self.scene, params, plug_flow=flow)

    @staticmethod
    def plug(model) -> PlugFlowConvection:
        """The plug-flow convection effect of a model."""
        return model.effect("convection")

    @staticmethod
    def with_layers(model, layer):
        """The model with the particles dealt to the layers ``layer`` (N,)."""
        return eqx.tree_at(lambda m: m.effect("convection").layer, model, jnp.asarray(layer))

    def remix_times(self) -> np.ndarray:
        """Times at which the particles are dealt to the layers anew, s (every ``t_R``,
        strictly before the end)."""
        t_end = float(self.times[-1])
        if self.layers == 1 or self.t_R is None:
            return np.zeros(0)
        k = np.arange(1, int(np.floor(t_end / self.t_R)) + 1) * self.t_R
        return k[k < t_end * (1 - 1e-12)]

    def shared(self) -> dict:
        return dict(super().shared(), **{"the layers and re-mixing (motion.layers, motion.t_R)":
                                         (self.layers, self.t_R)})

    def initial_state(self, params=None):
        model, T0 = self.model(params)
        if self.layers > 1:
            model = self.with_layers(model, self.deals[0])
        return {"model": model, "y": initial_state(model, T0),
                "deals": jnp.asarray(self.deals)}

    def advance(self, state, t0, t1):
        model, y = state["model"], state["y"]
        remix = self.remix_times()
        edges = np.union1d([t0, t1], remix[(remix > t0) & (remix < t1)])
        for a, b in zip(edges[:-1], edges[1:]):
            k = int(np.sum(remix <= a))  # re-mixings before this piece
            if k > 0 and np.any(remix == a):
                model = self.with_layers(model, state["deals"][k])
            y = self.solve(model, self.net, y, float(a), float(b))
        return dict(state, model=model, y=y)

    def observe(self, state) -> dict:
        model, y = state["model"], state["y"]
        row = super().observe(state)
        plug = self.plug(model)
        Ts = y["T"] if model.internal is None else y["T"][:, -1]
        row["T_gas_out"] = _outlet(plug, Ts, model.particles)
        row["layer"] = plug.layer
        if model.internal is not None:
            row["T_surface_mean"] = jnp.mean(y["T"][:, -1])
            row["T_centre_mean"] = jnp.mean(y["T"][:, 0])
        return row

    def bed_level_model(self, params=None):
        """The exercise's bed-level cooling curve at the output times, K, and its numbers.

        fluidized-bed-exercise.md sections 4-5: ``alpha_a`` from the scene's convection (at the
        gas temperature), ``alpha_i`` from Nu_i at ``Fo(t_E)`` (t_E = run.duration),
        ``1/k = 1/alpha_i + 1/alpha_a``, ``A/f = 6 m_1/(d rho_1)``, ``NTU = k (A/f)/(mdot_2
        c_p,2)`` and the closed form ``T1(t)``. Uses the first group (equal spheres).
        """
        scene = self.scene
        value = assemble.scene_values(scene, params)
        model, _ = self.model(params)
        plug = self.plug(model)
        conv = plug.convection
        p = model.particles
        d = p.diameter[:1]
        rho_c = p.capacity[:1] / (jnp.pi * d**3 / 6.0)
        rho1 = p.mass[:1] / (jnp.pi * d**3 / 6.0)
        alpha = conv.alpha(jnp.full(p.diameter.shape, conv.gas_temperature), p)[:1]
        if scene.heat.convection.internal_resistance == "transient-sphere":
            k = alpha
        else:
            lam1 = jnp.asarray(assemble.group_property(scene, value, 0, "conductivity"), float)
            k = series_with_transient_sphere(alpha, d, lam1, rho_c, value("run.duration"))
        cp2 = assemble.gas_state(scene, value).heat_capacity
        m1, mdot2 = value("motion.loading"), value("gas.mass_flux")
        A_f = corr.bed_area_per_cross_section(m1, d, rho1)
        ntu = corr.bed_ntu(k, A_f, mdot2, cp2)
        c1 = rho_c / rho1
        T = corr.batch_bed_mean_temperature(jnp.asarray(self.times), value("groups.0.temperature"),
                                            value("gas.temperature"), ntu, m1, c1, mdot2, cp2)
        info = dict(alpha_a=float(alpha[0]) if scene.heat.convection.internal_resistance == "none"
                    else None, k=float(k[0]), A_per_f=float(A_f[0]), NTU=float(ntu[0]))
        return np.asarray(T), info

    def start_log(self, state, params=None, spool=None):
        return {"params": params}

    def finish(self, rows, log, state) -> Trajectory:
        arrays = self.trajectory_arrays(rows, state)
        r = self.stack_rows(rows)
        model = state["model"]
        T_bed, info = self.bed_level_model(log["params"])
        n_out, N = len(self.times), model.particles.diameter.shape[0]
        extra = {"T_gas_out": r["T_gas_out"], "T_bed_level": T_bed}
        for key in ("T_surface_mean", "T_centre_mean"):
            if key in r:
                extra[key] = r[key]
        # positions: height of the particle's layer in a bed at the loosening porosity
        # (H = m_1 / (rho_1 (1 - psi_L)), fluidized-bed-exercise.md section 2), x = z = 0
        rho1 = float(model.particles.mass[0] / (np.pi * model.particles.diameter[0] ** 3 / 6))
        H = self.scene.motion.loading / (rho1 * (1 - self.scene.heat.convection.loosening_porosity))
        pos = np.zeros((n_out, N, 3))
        pos[:, :, 1] = (r["layer"] + 0.5) / self.layers * H
        return Trajectory(
            **arrays, position=pos, diameter=np.asarray(model.particles.diameter),
            n_contacts=np.zeros(n_out), n_wall_contacts=np.zeros(n_out),
            wall_area=np.zeros(n_out), extra=extra, info={"bed_level": info})

"""Motion model ``static``: a resting packing whose contacts are found once from geometry.

weigler-thermal-dem.md section 6.2 (appendix A5.1): the decoupled solver on a fixed contact
matrix. Here the contacts are pair lists (:mod:`drumheat.thermal.network`) and the balance
[2.13] is integrated by :func:`integrate_network`.
"""

from __future__ import annotations

import jax
import jax.numpy as jnp
import numpy as np

from drumheat.assemble import (group_index, initial_packing, initial_temperatures, make_particles,
                          output_times, scene_values)
from drumheat.runner.progress import SimProgress
from drumheat.scene import Scene, SceneError
from drumheat.thermal.composer import ThermalModel, make_thermal_model
from drumheat.thermal.integrate import (ThermalStabilityError, advance_adaptive,
                                        advance_explicit, check_explicit_step, initial_state)
from drumheat.thermal.network import ContactNetwork, find_contacts_2d_drum
from drumheat.motion.trajectory import Trajectory


def _concrete(x):
    try:
        return float(x)
    except (jax.errors.ConcretizationTypeError, jax.errors.TracerArrayConversionError, TypeError):
        return None


def integrate_network(scene: Scene, model: ThermalModel, net: ContactNetwork, y0, t_out,
                      progress: SimProgress | None = None, t_offset: float = 0.0,
                      autodiff: str = "reverse"):
    """Integrate the thermal state over the output times on a fixed contact network.

    Parameters
    ----------
    scene : Scene
        Supplies the solver choice and tolerances (``[run]``).
    model, net : ThermalModel, ContactNetwork
    y0 : dict
        State at ``t_out[0]`` (:func:`drumheat.thermal.integrate.initial_state`).
    t_out : array_like (n_out,)
        Output times, s; ``t_out[0]`` is the start.
    progress : SimProgress, optional
        Updated with the absolute time ``t_offset + t`` after every output interval.
    autodiff : {"reverse", "forward"}
        Autodiff mode the adaptive solves support (:func:`advance_adaptive`).

    Returns
    -------
    states : list of dict
        The state at every output time (``states[0] is y0``). Differentiable.

    Raises
    ------
    SceneError
        If the explicit solver's step ``run.dt`` exceeds the stability limit.
    """
    run = scene.run
    if model.internal is not None:
        return _integrate_shells(scene, model, net, y0, t_out, progress, t_offset)
    dt = None
    if run.solver == "explicit":
        limit = _concrete(model.stability_limit(net))
        try:
            dt = check_explicit_step(model, net, run.dt) if limit is not None else (
                run.dt or np.inf)
        except ThermalStabilityError as err:
            raise SceneError("run.dt", run.dt, str(err), scene.name) from None
    states = [y0]
    y = y0
    for t0, t1 in zip(t_out[:-1], t_out[1:]):
        if run.solver == "explicit":
            y = advance_explicit(model, net, y, float(t0), float(t1), dt)
        else:
            y = advance_adaptive(model, net, y, jnp.asarray(t0, float), jnp.asarray(t1, float),
                                 run.rtol, run.atol, implicit=run.solver == "implicit",
                                 autodiff=autodiff)
        states.append(y)
        if progress is not None:
            progress.update_to(t_offset + t1)
    return states


def _integrate_shells(scene, model, net, y0, t_out, progress, t_offset):
    """:func:`integrate_network` for particles with radial shells ([heat.internal])."""
    from drumheat.thermal.integrate import advance_shells
    from drumheat.thermal.internal import ShellStepError, plan_step

    try:
        scheme, dt = plan_step(model, net, y0["T"], float(t_out[-1] - t_out[0]))
    except ShellStepError as err:
        raise SceneError("heat.internal.dt", scene.heat.internal.dt, str(err), scene.name) from None
    states, y = [y0], y0
    for t0, t1 in zip(t_out[:-1], t_out[1:]):
        y = advance_shells(model, net, y, float(t0), float(t1), dt, scheme)
        states.append(y)
        if progress is not None:
            progress.update_to(t_offset + t1)
    return states


def stack_states(states, accounts, model: ThermalModel | None = None):
    """Stack a list of states into ``T (n_out, N)`` and ``{account: (n_out,)}``.

    With internal conduction (``model.internal``) ``T`` is each particle's enthalpy-mean
    temperature (staltner [7.1]-[7.3]); the profiles are in the states.
    """
    T = jnp.stack([s["T"] for s in states])
    if model is not None and model.internal is not None:
        T = model.internal.mean_temperature(T)
    Q = {a: jnp.stack([s["Q"][a] for s in states]) for a in accounts}
    return T, Q


class StaticBed:
    """A resting bed: packing and contacts built once, temperatures solved for any parameters.

    Parameters
    ----------
    scene : Scene

    Attributes
    ----------
    autodiff : {"reverse", "forward"}
        How :meth:`solve` may be differentiated: ``"reverse"`` (default, ``jax.grad``) or
        ``"forward"`` (``jax.jacfwd``; set by :mod:`drumheat.analysis.calibrate`).
    t_out : ndarray
        Output times of :meth:`solve`, s (from the scene; may be replaced by any increasing
        grid starting at 0).
    packing : drumheat.mechanics.deposition.Packing
    net : ContactNetwork
        Particle-particle contacts and contacts with the drum shell (wall id 0).
    """

    autodiff = "reverse"
    #: ``drumheat.run(..., devices=)`` may split the particle axis of this model's arrays
    supports_particle_sharding = True
    #: device mesh over which the particle arrays are split (set by the runner), or None
    mesh = None

    def __init__(self, scene: Scene):
        self.scene = scene
        self.packing = initial_packing(scene)
        pairs, wall = find_contacts_2d_drum(self.packing.position, self.packing.diameter,
                                            scene.drum.diameter,
                                            scene.packing.contact_tolerance)
        self.pairs, self.wall_particles = pairs, wall
        self.net = ContactNetwork.from_arrays(pairs, wall)
        self.t_out = output_times(scene)

    def model(self, params=None) -> tuple[ThermalModel, jax.Array]:
        """Thermal model and initial temperatures for parameter overrides ``params``."""
        value = scene_values(self.scene, params)
        model = make_thermal_model(self.scene, make_particles(self.scene, value), value)
        return model, initial_temperatures(self.scene, value)

    def solve(self, params=None, progress: SimProgress | None = None):
        """Temperatures ``(n_out, N)`` and exchanged heat ``{account: (n_out,)}``.

        Differentiable with respect to the values in ``params`` (dotted scene keys).
        """
        model, T0 = self.model(params)
        if self.mesh is not None:
            from drumheat.runner.sharding import shard_particles

            model, T0 = shard_particles((model, T0), self.mesh, self.scene.n_particles)
        states = integrate_network(self.scene, model, self.net, initial_state(model, T0),
                                   self.t_out, progress, autodiff=self.autodiff)
        self._last_states = states
        return stack_states(states, model.accounts, model)

    def trajectory(self, params=None, progress: bool | None = True) -> Trajectory:
        """Run the scene and collect what the result files need."""
        model, _ = self.model(params)
        with SimProgress(self.scene.run.duration, progress) as bar:
            T, Q = self.solve(params, bar)
        return self.make_trajectory(model, T, Q, self._last_states)

    def make_trajectory(self, model: ThermalModel, T, Q, states) -> Trajectory:
        """The :class:`Trajectory` of a solved run (``T``, ``Q`` from :func:`stack_states`,
        ``states`` the list of states at the output times)."""
        n_out = len(self.t_out)
        d = self.packing.diameter
        return Trajectory(
            t=self.t_out, T=np.asarray(T), Q={k: np.asarray(v) for k, v in Q.items()},
            position=np.broadcast_to(self.packing.position, (n_out,) + self.packing.position.shape),
            diameter=d, mass=np.asarray(model.particles.mass),
            capacity=np.asarray(model.particles.capacity), group=group_index(self.scene),
            n_contacts=np.full(n_out, len(self.pairs)),
            n_wall_contacts=np.full(n_out, len(self.wall_particles)),
            wall_area=np.full(n_out, float(np.sum(d[self.wall_particles] ** 2))),
            stored_heat=shell_stored_heat(model, states))


def shell_stored_heat(model: ThermalModel, states):
    """Stored heat change since the first state (J, (n_out,)) from the shell enthalpies, or None
    for lumped particles (the runner then uses ``sum m c (T - T0)``)."""
    if model.internal is None:
        return None
    H = np.asarray([float(jnp.sum(model.internal.stored_heat(s["T"]))) for s in states])
    return H - H[0]

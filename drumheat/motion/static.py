"""Motion model ``static``: a resting packing whose contacts are found once from geometry.

weigler-thermal-dem.md section 6.2 (appendix A5.1): the decoupled solver on a fixed contact
matrix. Here the contacts are pair lists (:mod:`drumheat.thermal.network`) and the balance
[2.13] is integrated by the run's thermal solver (:mod:`drumheat.thermal.solvers`).

The state is ``{"model": ThermalModel, "net": ContactNetwork, "y": {"T", "Q"}}``: the thermal
parameters and the network travel in the state, so an ensemble of variants (other parameters,
other packings) is one vmapped program and a calibration differentiates through it.
"""

from __future__ import annotations

import copy
import dataclasses

import jax
import jax.numpy as jnp
import numpy as np

from drumheat import assemble
from drumheat.motion.base import AbstractMotion, register
from drumheat.motion.trajectory import Trajectory
from drumheat.scene import Scene, SceneError
from drumheat.thermal.internal import ShellStepError
from drumheat.thermal.network import ContactNetwork, find_contacts_2d_drum
from drumheat.thermal.solvers import ThermalStabilityError, initial_state, plan_solver

__all__ = ["ThermalBed", "StaticBed", "thermal_solver", "pad_network", "polar_angle",
           "drum_wall_arrays"]


def thermal_solver(scene: Scene, model, net, T0, autodiff: str = "reverse"):
    """The run's thermal solver from ``[run]`` (:func:`drumheat.thermal.solvers.plan_solver`),
    an unstable step refused as a :class:`SceneError` naming the key."""
    run = scene.run
    try:
        return plan_solver(run.solver, model, net, T0, float(run.duration), rtol=run.rtol,
                           atol=run.atol, dt=run.dt, autodiff=autodiff)
    except ThermalStabilityError as err:
        raise SceneError("run.dt", run.dt, str(err), scene.name) from None
    except ShellStepError as err:
        raise SceneError("heat.internal.dt", scene.heat.internal.dt, str(err),
                         scene.name) from None


def pad_network(net: ContactNetwork, n_pairs: int, n_wall: int) -> ContactNetwork:
    """``net`` with zero-weight slots appended up to ``n_pairs`` pairs and ``n_wall`` wall
    contacts (the shapes an ensemble's variants share)."""
    def pad(a, n, fill):
        a = jnp.asarray(a)
        return jnp.concatenate([a, jnp.full((n - a.shape[0],) + a.shape[1:], fill, a.dtype)])

    angle = None if net.wall_angle is None else pad(net.wall_angle, n_wall, 0.0)
    return ContactNetwork(pad(net.pair_i, n_pairs, 0), pad(net.pair_j, n_pairs, 0),
                          pad(net.pair_weight, n_pairs, 0.0), pad(net.wall_particle, n_wall, 0),
                          pad(net.wall_id, n_wall, 0), pad(net.wall_weight, n_wall, 0.0), angle,
                          net.pair_unit)


def polar_angle(position) -> np.ndarray:
    """Polar angle of each position about the drum axis (counter-clockwise from +x), rad; the
    drum wall's segments are found from it (:mod:`drumheat.thermal.drum_wall`)."""
    position = np.asarray(position, float)
    return np.arctan2(position[:, 1], position[:, 0])


def drum_wall_arrays(rows: dict, drum_wall) -> dict:
    """The drum wall's part of a :class:`Trajectory` (``Trajectory.drum_wall``) from the
    stacked output rows of its state ``{"T": (n_out, n_seg), "Q": {"outside", "gas"}}``:
    ``T`` (n_out, n_seg) K, ``Q_outside`` and ``Q_gas`` (n_out,) J since t = 0 (in from
    outside, out to the free gas), ``capacity`` (n_seg,) J/K and ``area`` (n_seg,) m2."""
    n = drum_wall.n_segments
    return {"T": np.asarray(rows["T"], float),
            "Q_outside": np.asarray(rows["Q"]["outside"], float),
            "Q_gas": np.asarray(rows["Q"]["gas"], float),
            "capacity": np.full(n, float(drum_wall.capacity)),
            "area": np.full(n, float(drum_wall.area))}


class ThermalBed(AbstractMotion):
    """Base of the motion models whose heat is integrated by a thermal solver between output
    times on a network known in advance (static, random, fluidized, replay)."""

    differentiable = True
    #: the contact network of the bed (set by the subclass)
    net: ContactNetwork
    solver = None

    def model(self, params=None):
        """Thermal model and initial temperatures for parameter values ``params``."""
        return assemble.thermal_model(self.scene, params)

    def with_options(self, *, times=None, autodiff: str | None = None) -> "ThermalBed":
        """A copy with other output times (any increasing grid from 0) or another
        differentiation mode of the adaptive solver (``"reverse"`` or ``"forward"``); this
        object stays as it is."""
        new = copy.copy(self)
        if times is not None:
            new.times = np.asarray(times, float)
        if autodiff is not None and self.solver is not None:
            new.solver = self.solver.with_autodiff(autodiff)
        return new

    def shared(self) -> dict:
        return dict(super().shared(), **{"the thermal solver": repr(self.solver)})

    def cost(self, state, in_place: bool = False) -> dict | None:
        """For runs of many output intervals (each a solver call): the time of one interval,
        timed after a compiling call, times their number."""
        import time

        n = len(self.times) - 1
        if n < 200:
            return None  # a few hundred solver calls: seconds
        t0, t1 = float(self.times[0]), float(self.times[1])
        jax.block_until_ready(self.advance(state, t0, t1))
        start = time.perf_counter()
        jax.block_until_ready(self.advance(state, t0, t1))
        per = time.perf_counter() - start
        return dict(seconds=n * per, chunks=n, text=f"{n} output intervals of about "
                    f"{per:.2g} s each", cheaper="fewer outputs (run.output_interval), a shorter "
                    "run (run.duration)")

    def solve(self, model, net, y, t0, t1):
        """The run's thermal solver over ``[t0, t1]``; a stiff scene that exhausts the adaptive
        solver's steps is refused naming ``run.solver`` (diffrax's own message names an
        argument that is no scene key)."""
        try:
            return self.solver.advance(model, net, y, t0, t1)
        except Exception as err:  # noqa: BLE001 - equinox's runtime error of the solve
            if "maximum number of solver steps" not in str(err):
                raise
            raise SceneError("run.solver", self.scene.run.solver,
                             "the adaptive solver needed more than "
                             f"{getattr(self.solver, 'max_steps', 0):,} steps for one output "
                             "interval: the scene is stiff (large coefficients for small "
                             "particles); use run.solver = 'implicit' or a shorter "
                             "run.output_interval", self.scene.name) from None

    def observe(self, state) -> dict:
        model, y = state["model"], state["y"]
        if model.drum_wall is not None:
            return {"T": y["T"], "Q": y["Q"], "wall": y["wall"]}
        if model.internal is None:
            return {"T": y["T"], "Q": y["Q"]}
        return {"T": model.internal.mean_temperature(y["T"]), "Q": y["Q"],
                "stored_heat": jnp.sum(model.internal.stored_heat(y["T"]))}

    def trajectory_arrays(self, rows, state) -> dict:
        """The common :class:`Trajectory` fields from the stacked rows."""
        r = self.stack_rows(rows)
        model = state["model"]
        out = dict(t=np.asarray(self.times), T=r["T"], Q=r["Q"],
                   mass=np.asarray(model.particles.mass),
                   capacity=model.particles.host_capacity(),
                   group=assemble.group_index(self.scene))
        if "stored_heat" in r:
            out["stored_heat"] = r["stored_heat"] - r["stored_heat"][0]
        if "wall" in r:
            out["drum_wall"] = drum_wall_arrays(r["wall"], model.drum_wall)
        return out


@register
class StaticBed(ThermalBed):
    """A resting bed: packing and contacts built once, temperatures solved for any parameters.

    Attributes
    ----------
    packing : drumheat.mechanics.deposition.Packing
    net : ContactNetwork
        Particle-particle contacts and contacts with the drum shell (wall id 0).
    solver : thermal solver of the run (from ``[run]``)
    """

    name = "static"
    vmappable = True
    particle_shardable = True

    def __init__(self, scene: Scene):
        super().__init__(scene)
        self.packing = assemble.initial_packing(scene)
        gap_pp, gap_pw = assemble.conduction_gaps(scene)
        pairs, wall = find_contacts_2d_drum(self.packing.position, self.packing.diameter,
                                            scene.drum.diameter, gap_pp, wall_tolerance=gap_pw)
        self.pairs, self.wall_particles = pairs, wall
        self.net = ContactNetwork.from_arrays(pairs, wall)
        if scene.heat.drum_wall is not None:  # each wall contact's angle: its wall segment
            self.net = dataclasses.replace(self.net, wall_angle=jnp.asarray(
                polar_angle(self.packing.position)[wall], float))
        model, T0 = self.model()
        self.solver = thermal_solver(scene, model, self.net, T0)

    def initial_state(self, params=None):
        model, T0 = self.model(params)
        return {"model": model, "net": self.net, "y": initial_state(model, T0)}

    def advance(self, state, t0, t1):
        return dict(state, y=self.solve(state["model"], state["net"], state["y"], t0, t1))

    def align(self, states):
        n_pairs = max(int(s["net"].pair_i.shape[0]) for s in states)
        n_wall = max(int(s["net"].wall_particle.shape[0]) for s in states)
        return [dict(s, net=pad_network(s["net"], n_pairs, n_wall)) for s in states]

    def finish(self, rows, log, state) -> Trajectory:
        n_out = len(self.times)
        d = self.packing.diameter
        pos = self.packing.position
        return Trajectory(
            **self.trajectory_arrays(rows, state), diameter=d,
            position=np.broadcast_to(pos, (n_out,) + pos.shape),
            n_contacts=np.full(n_out, len(self.pairs)),
            n_wall_contacts=np.full(n_out, len(self.wall_particles)),
            wall_area=np.full(n_out, float(np.sum(d[self.wall_particles] ** 2))))

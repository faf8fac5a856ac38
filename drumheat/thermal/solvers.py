"""Time integration of the particle energy balances (weigler-thermal-dem.md eqs. [2.7], [2.13]).

The state is ``{"T": (N,) K, "Q": {account: J}}``: particle temperatures plus the cumulative
heat received from each outside reservoir, so that every run can report its own energy balance.

Solvers are objects (diffrax style), built once per run by :func:`plan_solver` from the
``[run]`` choices and the model's stability limit: :class:`Adaptive`, :class:`Explicit` and
:class:`Shells`, each with ``advance(model, net, y, t0, t1) -> y``. Two families:

* adaptive (diffrax): ``Tsit5`` (explicit Runge-Kutta with error control) or ``Kvaerno5``
  (implicit, for stiff scenes such as very large wall coefficients), tolerances from the scene;
* explicit: fixed-step forward Euler whose step must respect ``dt < m c / sum(alpha A)``
  (eq. [2.2]); a larger step is refused, never run.

With ``[heat.internal]`` (``model.internal`` not None) the state's ``T`` is ``(N, n_shells)``
and :func:`advance_shells` replaces both: fixed steps of the unconditionally stable implicit
shell scheme or of the thesis' explicit scheme with its limit enforced
(:mod:`drumheat.thermal.internal`); :func:`drumheat.thermal.internal.plan_step` chooses the step.
"""

from __future__ import annotations

import abc
import math

import diffrax
import equinox as eqx
import jax
import jax.numpy as jnp

from drumheat.thermal import internal
from drumheat.thermal.model import ThermalModel
from drumheat.thermal.network import ContactNetwork


class ThermalStabilityError(ValueError):
    """An explicit thermal step above the stability limit was asked for."""


def initial_state(model: ThermalModel, T0) -> dict:
    """ODE state at t = 0: temperatures and zero exchanged heat per account.

    ``T0`` (N,) particle temperatures; with internal conduction uniform profiles (N, n_shells).
    """
    T0 = jnp.asarray(T0, float)
    if model.internal is not None and T0.ndim == 1:
        T0 = model.internal.initial(T0)
    y = {"T": T0, "Q": {a: jnp.zeros((), T0.dtype) for a in model.accounts}}
    if model.drum_wall is not None:  # the drum wall's segments (drumheat.thermal.drum_wall)
        y["wall"] = model.drum_wall.initial()
    return y


def _vector_field(t, y, args):
    model, net = args
    if model.drum_wall is not None:
        return _wall_vector_field(t, y, model, net)
    q, external = model.heat_flows(y["T"], net)
    return {"T": q / model.particles.capacity, "Q": external}


def _wall_vector_field(t, y, model, net):
    """The right-hand side with the drum wall's segments (``y["wall"]``): particle and segment
    temperatures and the bed's and the wall's accounts (:meth:`ThermalModel.heat_flows_wall`)."""
    q, external, rate, wall_flows = model.heat_flows_wall(y["T"], y["wall"], net, t)
    return {"T": q / model.particles.capacity, "Q": external,
            "wall": {"T": rate, "Q": wall_flows}}


@eqx.filter_jit
def advance_adaptive(model: ThermalModel, net: ContactNetwork, y, t0, t1, rtol, atol,
                     implicit: bool = False, max_steps: int = 100_000,
                     autodiff: str = "reverse"):
    """Advance the state from t0 to t1 with diffrax (Tsit5, or Kvaerno5 if ``implicit``).

    ``autodiff`` picks how the solve may be differentiated: ``"reverse"`` (``jax.grad``,
    diffrax ``RecursiveCheckpointAdjoint``) or ``"forward"`` (``jax.jvp``/``jax.jacfwd``,
    diffrax ``ForwardMode``; cheaper to compile and efficient for a few parameters). Each
    supports only its own mode; the values are identical.
    """
    solver = diffrax.Kvaerno5() if implicit else diffrax.Tsit5()
    adjoint = diffrax.ForwardMode() if autodiff == "forward" else diffrax.RecursiveCheckpointAdjoint()
    sol = diffrax.diffeqsolve(
        diffrax.ODETerm(_vector_field), solver, t0, t1, dt0=None, y0=y, args=(model, net),
        stepsize_controller=diffrax.PIDController(rtol=rtol, atol=atol),
        saveat=diffrax.SaveAt(t1=True), max_steps=max_steps, adjoint=adjoint)
    return jax.tree_util.tree_map(lambda a: a[-1], sol.ys)


def explicit_steps(t0, t1, dt) -> tuple[int, float]:
    """Number of equal explicit steps covering [t0, t1] with steps <= dt, and that step."""
    n = max(1, math.ceil((t1 - t0) / dt - 1e-9))
    return n, (t1 - t0) / n


@eqx.filter_jit
def _euler_scan(model, net, y, h, n_steps: int):
    def body(y, _):
        dy = _vector_field(None, y, (model, net))
        return jax.tree_util.tree_map(lambda a, b: a + h * b, y, dy), None

    y, _ = jax.lax.scan(body, y, None, length=n_steps)
    return y


@eqx.filter_jit
def _euler_scan_timed(model, net, y, t0, h, n_steps: int):
    """:func:`_euler_scan` for a right-hand side that depends on time (the drum wall's
    segments turn with the drum): step k is evaluated at ``t0 + k h``."""
    def body(y, k):
        dy = _vector_field(t0 + k * h, y, (model, net))
        return jax.tree_util.tree_map(lambda a, b: a + h * b, y, dy), None

    y, _ = jax.lax.scan(body, y, jnp.arange(n_steps, dtype=jnp.float64))
    return y


def advance_explicit(model: ThermalModel, net: ContactNetwork, y, t0: float, t1: float,
                     dt: float):
    """Advance from t0 to t1 with forward Euler steps no larger than ``dt``.

    The caller checks ``dt`` against :meth:`ThermalModel.stability_limit` first
    (:func:`check_explicit_step`).
    """
    n, h = explicit_steps(t0, t1, dt)
    if model.drum_wall is not None:
        return _euler_scan_timed(model, net, y, jnp.asarray(t0, float), jnp.asarray(h, float), n)
    return _euler_scan(model, net, y, h, n)


def check_explicit_step(model: ThermalModel, net: ContactNetwork, dt: float | None,
                        safety: float = 0.5) -> float:
    """Explicit step to use: ``dt`` if below the stability limit, else refuse.

    Parameters
    ----------
    dt : float or None
        Requested step, s; ``None`` picks ``safety`` times the limit.

    Raises
    ------
    ThermalStabilityError
        If ``dt`` exceeds ``m c / sum(alpha A)`` (weigler-thermal-dem.md eq. [2.2]).
    """
    limit = float(model.stability_limit(net))
    if dt is None:
        return safety * limit if math.isfinite(limit) else math.inf
    if dt > limit:
        raise ThermalStabilityError(
            f"explicit thermal step dt = {dt:.4g} s exceeds the stability limit "
            f"min(m c / sum(alpha A)) = {limit:.4g} s (weigler eq. [2.2]); use dt <= "
            f"{limit:.4g} s or an adaptive/implicit solver")
    return dt


@eqx.filter_jit
def _shell_scan(model, net, y, h, n_steps: int, scheme: str):
    step = internal.implicit_step if scheme == "implicit" else internal.explicit_step

    def body(y, _):
        T, dQ = step(model, net, y["T"], h)
        return {"T": T, "Q": {a: y["Q"][a] + dQ[a] for a in y["Q"]}}, None

    y, _ = jax.lax.scan(body, y, None, length=n_steps)
    return y


def advance_shells(model: ThermalModel, net: ContactNetwork, y, t0: float, t1: float,
                   dt: float, scheme: str = "implicit"):
    """Advance a shell state from t0 to t1 in equal steps no larger than ``dt``.

    ``scheme`` "implicit" (backward Euler, any dt) or "explicit" (the caller has checked dt
    with :func:`drumheat.thermal.internal.plan_step`; each step checks again at run time and
    raises rather than run above the limit).
    """
    n, h = explicit_steps(t0, t1, dt)
    return _shell_scan(model, net, y, jnp.asarray(h, float), n, scheme)


# ---------------------------------------------------------------------------------------------
# solvers as objects
# ---------------------------------------------------------------------------------------------


class AbstractThermalSolver(eqx.Module):
    """Advances the thermal state ``y`` over ``[t0, t1]`` on a fixed contact network."""

    @abc.abstractmethod
    def advance(self, model: ThermalModel, net: ContactNetwork, y, t0, t1):
        """The state at ``t1`` from the state ``y`` at ``t0``."""

    def with_autodiff(self, mode: str) -> "AbstractThermalSolver":
        """This solver supporting differentiation mode ``mode`` ("reverse" or "forward");
        fixed-step solvers support both as they are."""
        return self


class Adaptive(AbstractThermalSolver):
    """diffrax Tsit5 (or Kvaerno5 with ``implicit``) with PID step control.

    ``autodiff`` is the differentiation mode the solve supports: ``"reverse"`` (``jax.grad``)
    or ``"forward"`` (``jax.jvp`` / ``jax.jacfwd``; cheaper for a few parameters). ``t0`` and
    ``t1`` may be traced.
    """

    rtol: float = eqx.field(static=True)
    atol: float = eqx.field(static=True)
    implicit: bool = eqx.field(static=True, default=False)
    autodiff: str = eqx.field(static=True, default="reverse")
    max_steps: int = eqx.field(static=True, default=100_000)

    def with_autodiff(self, mode: str) -> "Adaptive":
        return Adaptive(self.rtol, self.atol, self.implicit, mode, self.max_steps)

    def advance(self, model, net, y, t0, t1):
        return advance_adaptive(model, net, y, jnp.asarray(t0, float), jnp.asarray(t1, float),
                                self.rtol, self.atol, implicit=self.implicit,
                                max_steps=self.max_steps, autodiff=self.autodiff)


class Explicit(AbstractThermalSolver):
    """Forward Euler in equal steps no larger than ``dt`` (checked against the stability limit
    by :func:`plan_solver`); ``t0`` and ``t1`` must be concrete (they fix the step count)."""

    dt: float = eqx.field(static=True)

    def advance(self, model, net, y, t0, t1):
        return advance_explicit(model, net, y, float(t0), float(t1), self.dt)


class Shells(AbstractThermalSolver):
    """The shell schemes of :mod:`drumheat.thermal.internal` (``scheme`` "implicit" or
    "explicit") in equal steps no larger than ``dt``; ``t0``, ``t1`` concrete."""

    scheme: str = eqx.field(static=True)
    dt: float = eqx.field(static=True)

    def advance(self, model, net, y, t0, t1):
        return advance_shells(model, net, y, float(t0), float(t1), self.dt, self.scheme)


def plan_solver(kind: str, model: ThermalModel, net: ContactNetwork, T0, t_span: float, *,
                rtol: float = 1e-8, atol: float = 1e-6, dt: float | None = None,
                autodiff: str = "reverse") -> AbstractThermalSolver:
    """The solver of a run: ``kind`` "adaptive", "implicit" or "explicit" (``[run] solver``);
    particles with shells always get :class:`Shells`.

    The explicit step is ``dt`` if below the stability limit, else refused; without ``dt``
    half the limit. Where the model's values are traced (a fit) the limit cannot be read:
    the explicit step is then ``dt`` as given (or one step per call when none is given).

    Raises
    ------
    ThermalStabilityError
        For an explicit ``dt`` above the limit (weigler eq. [2.2]).
    drumheat.thermal.internal.ShellStepError
        For a shell step the scheme cannot take (:func:`drumheat.thermal.internal.plan_step`).
    """
    if model.internal is not None:
        scheme, h = internal.plan_step(model, net, initial_state(model, T0)["T"], t_span)
        return Shells(scheme, h)
    if kind == "explicit":
        try:
            limit = float(model.stability_limit(net))
        except (jax.errors.ConcretizationTypeError, jax.errors.TracerArrayConversionError,
                TypeError):
            return Explicit(dt if dt is not None else math.inf)
        del limit  # concrete: check_explicit_step reads it again with the numbers
        return Explicit(check_explicit_step(model, net, dt))
    return Adaptive(rtol, atol, implicit=kind == "implicit", autodiff=autodiff)

"""The DEM contact loop in C++ on CPU (opt-in: ``make_dem(..., pair_kernel="cpu")``).

On XLA:CPU the JAX force kernel of :mod:`drumheat.mechanics.integrator` runs as some twenty
passes over the pair slots plus scatter-adds, about a third of LIGGGHTS' speed per core
(docs/performance.md). ``contact_kernel.cc`` computes the same contact law
(:func:`drumheat.mechanics.contact_forces.contact_law` and
:func:`~drumheat.mechanics.contact_forces.rolling_torque`: Weigler digest,
shared/reference/weigler-thermal-dem.md sec. 4 [2.1]-[2.4] and sec. 5; LIGGGHTS ``hooke`` with
tangential history, shared/peers/liggghts/README.md) for the particle-particle pairs and the
particle-wall contacts in one loop, called through ``jax.ffi`` (an XLA custom call); the wall
geometry (distance, normal, surface velocity of every wall at every particle) still comes from
the JAX walls, so every wall type works. With ``make_dem(..., conduction=...)`` the same loop
sums the contact heat flows (:mod:`drumheat.mechanics.conduction`, both laws, with its gap
tolerance). The loop is cut into as many chunks as XLA's intra-op thread pool has threads (at
most one per 8 000 listed pairs; ``DRUMHEAT_KERNEL_THREADS`` sets the number), each a range of
particles with about as many listed pairs as the others (the list is grouped by the first
particle), and run on that pool, so no threads are started per step: the pool's threads stay
with the call for all its passes (and a run's steps); each chunk sums into its own buffer and
the buffers are added in chunk order, so the result depends on the chunk count and on the
listed pairs by round-off and on nothing else. Once the particles' numbering has lost most of
its pairs near in memory (a mixed bed), the lists of such runs go over to the cell order
(``NeighborList.order``, :mod:`drumheat.mechanics.neighbors`): the loop then lays the
particles' data out in that order and takes the pairs as listed, so that it reads memory in
the order of the particles' places
(what that is worth: docs/performance.md). The pair and wall springs are updated in place
(aliased buffers). Speed:
docs/performance.md (``scripts/bench_cpu_pair_kernel.py`` kernel against kernel,
``scripts/bench_vs_liggghts.py`` the whole step against LIGGGHTS).

The same library holds the neighbour rebuild of such runs (``neighbor_kernel.cc``,
:func:`neighbor_pairs`, its search on the same threads): the pairs of the XLA cell list in its
order (canonical, or grouped in the cell order) and, for carrying the springs and other
per-pair data, the old slot of each pair; :func:`take_pair_data_in_place` then carries each
per-pair array in its own buffer. And the coupled heat's contact conduction at each thermal
step (:func:`count_conduction`, for :class:`drumheat.thermal.contact.ContactConduction` on the
contact times the loop counted), which in XLA took eight passes over the pair slots.

Scope: 2D (monolayer: x-y, spin about z) and 3D, float32 and float64 mechanics, any number of
materials (per-type contact tables), rolling resistance, walls, pair conduction, friction
heat, optional periodic z; the CPU backend and single runs (not under ``vmap``, not
differentiable).

Friction heat (:mod:`drumheat.mechanics.dissipation`): each contact's loss in a step needs the
full-step velocities, known only after the forces of all contacts are summed and the second
half-kick is done. With ``wall_distance_before`` :func:`contacts` also writes one row per contact
(force, levers, rolling torque, change of its spring energy) and sums the loss rates by source;
:func:`contact_heat`, a second small pass at the full-step velocities, turns the rows into each
contact's loss and splits it between the partners, as
:func:`~drumheat.mechanics.dissipation.step_heat` does in JAX.
:func:`check_supported` says why a configuration is refused (:func:`unsupported_reasons`
without raising). The JAX kernel stays the reference and the path for GPUs, ensembles and
everything else; ``tests/test_cpu_kernel.py`` holds the two equal to round-off.

Build: :func:`available` compiles the source with ``$CXX`` (else the first of ``g++``, ``c++``,
``clang++`` on the PATH) and :data:`FLAGS` on first use into
``$DRUMHEAT_CACHE_DIR/kernels`` (default ``~/.cache/drumheat/kernels``), named by the hash of the
source, the flags and the jaxlib version, under a file lock (parallel processes build it once),
loads and registers it; a kernel already in the cache needs no compiler. Its answer
``(ok, reason)`` is kept for the process, so later calls cost nothing; when no compiler is found
or the build fails it answers ``(False, reason)`` in one sentence (the compiler's full output is
left in a ``.log`` beside the library) and raises nothing.
"""

from __future__ import annotations

import ctypes
import hashlib
import os
import shlex
import shutil
import subprocess
import time
from contextlib import contextmanager
from pathlib import Path

import jax
import jax.numpy as jnp
import numpy as np
from drumheat.devices import to_device
from drumheat.environment import cache_dir_setting

__all__ = ["TARGET", "HEAT_TARGET", "NEIGHBOR_TARGET", "TAKE_TARGET", "COUNT_CONDUCTION_TARGET",
           "available", "check_supported", "contacts", "contact_heat", "count_conduction",
           "kernel_params", "load",
           "neighbor_pairs", "take_pair_data_in_place", "unsupported_reasons"]

TARGET = "drumheat_contacts"
HEAT_TARGET = "drumheat_contact_heat"  # the friction heat's second pass
NEIGHBOR_TARGET = "drumheat_neighbors"
TAKE_TARGET = "drumheat_take_pairs"  # per-pair data carried to a rebuilt list in place
COUNT_CONDUCTION_TARGET = "drumheat_count_conduction"  # the coupled heat's contact conduction
SOURCE = Path(__file__).with_name("contact_kernel.cc")
#: the sources compiled into the one library: the contact loop and the neighbour rebuild
SOURCES = (SOURCE, Path(__file__).with_name("neighbor_kernel.cc"))
#: the headers both sources include (part of the library's cache key)
HEADERS = (Path(__file__).with_name("kernel_math.h"), Path(__file__).with_name("kernel_team.h"))
#: compiler flags. None changes a number: -ffp-contract=off keeps a * b + c two roundings in the
#: AVX2 / AVX-512 versions of the vector loops (contact_kernel.cc), which have fused
#: multiply-adds, so that every version gives the numbers of the baseline x86-64 build;
#: -fno-trapping-math and -fno-math-errno let the compiler compute both sides of a selection and
#: use the square-root instruction (nothing reads floating-point flags or errno), which those
#: loops need.
FLAGS = ("-O3", "-ffp-contract=off", "-fno-trapping-math", "-fno-math-errno", "-shared", "-fPIC",
         "-std=c++17", "-w")
COMPILERS = ("g++", "c++", "clang++")
COMPILE_TIMEOUT_S = 600
_STATE: tuple[bool, str] | None = None  # the answer of available(), once known
_REGISTERED: str | None = None  # the library registered as TARGET in this process


def _cache_dir() -> Path:
    env = cache_dir_setting()  # a compiled kernel needs a folder even with the JAX cache off
    return (Path(env) if env else Path.home() / ".cache" / "drumheat") / "kernels"


def _compiler() -> tuple[list[str] | None, str]:
    """The compiler command (``$CXX`` may hold words, e.g. ``ccache g++``), or None and why."""
    cxx = os.environ.get("CXX", "").strip()
    if cxx:
        words = shlex.split(cxx)
        path = shutil.which(words[0])
        if path is None:
            return None, f"the C++ compiler $CXX = {cxx!r} is not on the PATH"
        return [path, *words[1:]], ""
    for name in COMPILERS:
        path = shutil.which(name)
        if path is not None:
            return [path], ""
    return None, f"no C++ compiler found ($CXX unset, none of {', '.join(COMPILERS)} on the PATH)"


def _library_path() -> Path:
    import jaxlib

    texts = [f.read_text() for f in (*SOURCES, *HEADERS)]
    key = hashlib.sha256("\n".join([*texts, jaxlib.__version__, *FLAGS]).encode())
    return _cache_dir() / f"contact_kernel_{key.hexdigest()[:16]}.so"


@contextmanager
def _file_lock(path: Path):
    """An exclusive lock on ``path`` across processes (fcntl; a no-op where there is none)."""
    try:
        import fcntl
    except ImportError:  # pragma: no cover - not POSIX
        yield
        return
    with open(path, "a") as fh:
        fcntl.flock(fh, fcntl.LOCK_EX)
        try:
            yield
        finally:
            fcntl.flock(fh, fcntl.LOCK_UN)


def _build(out: Path) -> str:
    """Compile the kernel into ``out`` unless it is there; return '' or why it failed."""
    if out.exists():
        return ""
    try:
        out.parent.mkdir(parents=True, exist_ok=True)
    except OSError as e:
        return f"the kernel cache folder {out.parent} cannot be created ({e.strerror})"
    with _file_lock(out.with_suffix(".lock")):
        if out.exists():  # another process built it while this one waited
            return ""
        cmd, why = _compiler()
        if cmd is None:
            return why
        include = Path(jax.ffi.include_dir())
        if not (include / "xla" / "ffi" / "api" / "ffi.h").exists():
            return f"jaxlib ships no XLA FFI headers (looked in {include})"
        tmp = out.with_suffix(f".{os.getpid()}.tmp")
        log = out.with_suffix(".log")
        full = [*cmd, *FLAGS, f"-I{include}", *map(str, SOURCES), "-o", str(tmp)]
        t0 = time.perf_counter()
        try:
            proc = subprocess.run(full, capture_output=True, text=True, timeout=COMPILE_TIMEOUT_S)
        except (OSError, subprocess.TimeoutExpired) as e:
            tmp.unlink(missing_ok=True)
            return f"the C++ compiler {cmd[0]} could not build the kernel ({e})"
        log.write_text(f"$ {shlex.join(full)}\n# exit {proc.returncode} after "
                       f"{time.perf_counter() - t0:.1f} s\n{proc.stdout}{proc.stderr}")
        if proc.returncode != 0 or not tmp.exists():
            tmp.unlink(missing_ok=True)
            err = proc.stderr.strip().splitlines()
            first = next((ln for ln in err if ": error" in ln or ": fatal error" in ln),
                         err[0] if err else "no message").strip()
            return (f"compiling the C++ contact kernel with {cmd[0]} failed (exit "
                    f"{proc.returncode}: {first[:300]}; full output in {log})")
        os.replace(tmp, out)  # atomic: a reader sees the whole library or none
        log.unlink(missing_ok=True)  # a log is left only where a build failed
    return ""


def _probe() -> tuple[bool, str]:
    global _REGISTERED
    if jax.default_backend() != "cpu":
        return False, f"the default JAX backend is {jax.default_backend()!r}, not 'cpu'"
    if _REGISTERED is not None:  # registered earlier in this process (a target is for good)
        return True, ""
    out = _library_path()
    why = _build(out)
    if why:
        return False, why
    try:
        lib = ctypes.cdll.LoadLibrary(str(out))
        jax.ffi.register_ffi_target(TARGET, jax.ffi.pycapsule(lib.Contacts), platform="cpu")
        jax.ffi.register_ffi_target(HEAT_TARGET, jax.ffi.pycapsule(lib.ContactHeat),
                                    platform="cpu")
        jax.ffi.register_ffi_target(NEIGHBOR_TARGET, jax.ffi.pycapsule(lib.Neighbors),
                                    platform="cpu")
        jax.ffi.register_ffi_target(TAKE_TARGET, jax.ffi.pycapsule(lib.TakePairs),
                                    platform="cpu")
        jax.ffi.register_ffi_target(COUNT_CONDUCTION_TARGET,
                                    jax.ffi.pycapsule(lib.CountConduction), platform="cpu")
    except (OSError, AttributeError) as e:
        return False, f"the compiled C++ contact kernel {out} cannot be loaded ({e})"
    _REGISTERED = str(out)
    return True, ""


def available() -> tuple[bool, str]:
    """Whether the kernel can be used here, and why not: ``(ok, reason)``; never raises.

    The first call builds (or finds in the cache) and registers the kernel, about 20 s when it
    must compile; the answer is kept, so later calls are free (a ``contact_backend = "auto"``
    may ask every time it builds a DEM).
    """
    global _STATE
    if _STATE is None:
        try:
            _STATE = _probe()
        except Exception as e:  # noqa: BLE001 - the contract is an answer, not an exception
            _STATE = (False, f"the C++ contact kernel could not be prepared ({type(e).__name__}: "
                             f"{e})")
    return _STATE


def load() -> str:
    """Build and register the kernel (see :func:`available`); return its FFI target name.

    Raises RuntimeError naming the reason when it cannot be used.
    """
    ok, why = available()
    if not ok:
        raise RuntimeError(f"the C++ contact kernel is not available: {why}")
    return TARGET


def unsupported_reasons(dim, params, dtype, batch_axis) -> list[str]:
    """Why ``pair_kernel="cpu"`` cannot serve this configuration (empty: it can)."""
    reasons = []
    if dim not in (2, 3):
        reasons.append(f"it is written for 2D and 3D, not dim = {dim}")
    if jnp.dtype(dtype) not in (jnp.float32, jnp.float64):
        reasons.append(f"it runs float32 or float64 mechanics, not {jnp.dtype(dtype).name}")
    if batch_axis is not None:
        reasons.append("it does not batch under vmap (ensembles use the JAX kernel)")
    ok, why = available()
    if not ok:
        reasons.append(why)
    return reasons


def check_supported(dim, params, dtype, batch_axis) -> None:
    """Raise ValueError naming every reason why ``pair_kernel="cpu"`` cannot serve."""
    reasons = unsupported_reasons(dim, params, dtype, batch_axis)
    if reasons:
        raise ValueError("pair_kernel='cpu' cannot be used: " + "; ".join(reasons)
                         + ". Use pair_kernel='jax'.")


_TABLES = ("kn", "kt", "zeta_n", "zeta_t", "mu", "mu_roll")


def shared_value(values):
    """``values`` (a concrete per-particle array): its one value, a 0-d array of its dtype,
    where all particles share it, else the array as it is. A constant (N,) array that a
    compiled step closes over stays in memory as one of its inputs (and XLA may write it out
    anew where it is used); one value is broadcast in place (the integrator's inverse masses,
    :func:`uniform_or_all`)."""
    a = np.asarray(values)
    if a.size > 1 and np.all(a == a.reshape(-1)[0]):
        return to_device(a.reshape(-1)[0])
    return values


def uniform_or_all(values):
    """``values`` (a concrete per-particle array) as :func:`contacts` may take it: the one
    value, shape (1,), where all particles share it (:func:`shared_value`), else the array as
    it is."""
    a = np.asarray(values)
    if a.size > 1 and np.all(a == a.reshape(-1)[0]):
        return to_device(a.reshape(-1)[:1])
    return values


def kernel_params(params, n_walls, dtype, dt, wall_omega, periodic_length=None,
                  rotation=True) -> dict:
    """The static inputs of :func:`contacts` for a DEM: ``params`` (ContactParams) as the
    particle-particle tables (6, T, T) and the particle-wall tables (6, T, W) (the JAX kernel's
    ``table`` / ``wall_table``: kn, kt, zeta_n, zeta_t, mu, mu_roll), the walls' angular
    velocities about z (W,) rad/s, dt, the period of z and whether spins are integrated."""
    T = params.n_types
    pp = np.stack([np.broadcast_to(np.asarray(getattr(params, f"{k}_pp"), float), (T, T))
                   for k in _TABLES])
    pw = np.stack([np.broadcast_to(np.asarray(getattr(params, f"{k}_pw"), float), (T, n_walls))
                   for k in _TABLES])
    return dict(tables_pp=jnp.asarray(pp, dtype), tables_pw=jnp.asarray(pw, dtype),
                wall_omega=jnp.asarray(np.asarray(wall_omega, float).reshape(n_walls), dtype),
                dt=float(dt), periodic_length=periodic_length, rotation=bool(rotation))


def _rows(dim: int) -> tuple[int, int]:
    """Columns of the friction-heat rows of a pair and of a wall slot (contact_kernel.cc):
    force, the two levers (one at a wall), rolling torque and the change of spring energy."""
    dw = 3 if dim == 3 else 1
    return 3 * dim + dw + 1, 2 * dim + dw + 1


def contacts(pos, vel, omega, radius, mass, inertia, ptype, idx, spring, wall_distance,
             wall_normal, wall_velocity, wall_spring, *, tables_pp, tables_pw, wall_omega, dt,
             periodic_length=None, rotation=True, temperature=None, conduction_law=None,
             conduction_h=0.0, gap_tolerance=0.0, wall_distance_before=None,
             pair_gap=0.0, order=None, details=True, body_force=None, ahead=None, shell=None,
             wall_gap=None, drift=None, steps=None):
    """Particle-particle and particle-wall contact forces in one C++ loop.

    The mechanics run in the dtype of ``pos`` (float32 or float64); every float input is cast
    to it.

    Args:
      pos, vel: positions, velocities (N, D), D = 2 or 3; omega: spins (N, 3), or (N,) about z
        in 2D.
      radius, mass, inertia: (N,), or (1,) for one value that all particles share
        (:func:`uniform_or_all`); ptype: material type of each particle (N,) int (with one
        type, in ``tables_pp``, any length: it is not read).
      idx: (2, M) OrderedSparse neighbour pairs (padding N); spring: (M, D) tangential springs.
      wall_distance: (N, W) distance of each particle centre from each wall; wall_normal:
        (N, W, D) unit normal from the wall towards the particle; wall_velocity: (N, W, D)
        velocity of the wall surface at the particle (the three outputs of each wall's
        ``evaluate``, stacked over the walls; with ``shell``, of the walls 1 .. W - 1 only);
        wall_spring: (N, W, D) tangential springs.
      tables_pp, tables_pw, wall_omega, dt, periodic_length, rotation: from
        :func:`kernel_params`.
      temperature, conduction_law, conduction_h, gap_tolerance: with a law (``"projected"`` or
        ``"overlap"``, :mod:`drumheat.mechanics.conduction`), the heat flow through the
        conducting pairs (overlapping, or with a gap of at most ``gap_tolerance`` times the
        smaller diameter) at the temperatures (N,) float64 is summed in the same loop.
      wall_distance_before: friction heat (:mod:`drumheat.mechanics.dissipation`): the walls'
        distance (N, W) at the positions before the step's drift ``pos - dt vel`` and time
        ``t - dt``; with it the loop also returns what :func:`contact_heat` needs.

      pair_gap: the gap tolerance of ``conducts`` (times the smaller diameter).
      order: None, or the particles (N,) int32 in the order of their cells (``NeighborList.order``,
        a permutation), for a list grouped in that order (:func:`neighbor_pairs` with
        ``ranked``): the loop then copies the particles' data into that order and takes the
        pairs as listed, so that consecutive pairs and both partners of a pair lie near each
        other in memory however the particles are numbered, sums at the ranks and puts the sums
        back. Each sum takes its terms in the list's order, as without ``order``; its threads
        take ranges of ranks instead of indices (round-off, as another thread count).
      details: False: the per-pair overlap, centre distance and normal force are not written
        (returned with length 0).
      body_force: None, or a force added to each particle's contact force (gravity ``m g``):
        (N, D), or (1, D) for one row that all particles share (:func:`uniform_or_all`). The
        loop adds it to each particle's sum last, so the forces are those of ``body_force +
        force`` added in JAX, bit for bit, without XLA's pass over (N, D) after the call.
      ahead: None, or ``(constants, reference)`` for the coming step's skin test of the
        integrator's loop (:func:`skin_test_constants`; ``reference`` the neighbour list's
        reference positions (N, D)): the loop also returns the largest squared displacement
        from them after the coming step's two half-kicks and drift, for particles of one mass
        (contact_kernel.cc, the coming step's skin test).
      shell: None, or ``(R, omega)`` of a drum shell that is wall 0
        (:class:`drumheat.geometry.walls.DrumShell`: radius, m, and angular velocity, rad/s):
        the loop computes its distance, normal and velocity at each particle from the
        positions, with ``DrumShell.evaluate``'s arithmetic, and the wall geometry arguments
        cover the other walls. Not with ``wall_distance_before`` (friction heat).
      wall_gap: None, or the gap tolerance of the wall slots' conduction flags (times the
        particle's diameter; 0: the slots that touch), returned as ``wall_conducts``.
      drift: None, or ``(constants, force, torque)`` of the step's kicks and drift
        (:func:`drift_constants`; the forces (N, D) and torques of the step before): ``pos``,
        ``vel`` and ``omega`` are then the step before's, its velocities and spins with
        ``a`` times its last half-kick pending, and the loop first makes the step's two
        half-kicks and drift, for particles of one mass and moment of inertia, with XLA's
        roundings of the integrator's, and computes the contacts at the new positions and
        velocities, returned as ``drifted`` (contact_kernel.cc, the step's kicks and drift).
        Walls: none, or the drum shell alone (``shell``); not with ``wall_distance_before``.
      steps: None, or ``(most, half_skin_sq)`` (traced; with ``drift``, ``ahead`` and
        ``wall_gap``): a run of steps in the call. After the step, while fewer than ``most``
        are made and the coming step's skin test is at most ``half_skin_sq``, the loop makes
        the next step from the one before's outputs (its pending half-kick's factor 1): the
        steps of the integrator's loop between neighbour rebuilds, without a return to XLA
        between them (contact_kernel.cc, a run of steps). The outputs are then those of the
        last step, ``max_overlap`` the largest of all steps', and ``counted`` holds each pair
        slot's (M,) and wall slot's (N W,) count of the steps it conducted (int32) and the
        steps made (1,) int32.

    Returns ``(force, torque, spring, overlap, distance, normal_force, wall_spring,
    wall_overlap, wall_normal_force, max_overlap, heat, conducts, pair_rows, wall_rows,
    rates, ahead, wall_conducts, drifted, counted)``: contact forces (N, D) and torques (N, 3)
    or (N,) on the particles (torques zero without ``rotation``); per pair the new springs (M,
    D), overlap, centre distance and normal force (M, or length 0 without ``details``); per wall
    slot the new springs (N, W, D), overlap and normal force (N, W); all zero where nothing
    touches; the largest overlap / radius (the smaller radius of a pair) (1,); the heat flow
    into each particle (N,) float64, W (length 0 without a conduction law); whether each pair
    conducts (M,) bool: it overlaps or its surface gap is at most ``pair_gap`` times the smaller
    diameter (:meth:`drumheat.mechanics.forces.ContactForces.pair_gap_mask`, the same test);
    with ``wall_distance_before`` (else length 0) each contact's friction-heat row (pairs (M,
    K_p), wall slots (N W, K_w): force on B, levers, rolling torque, ``U_new - U_old``) and the
    step's losses at the continuous rates (3,) float64, J: damping, sliding, rolling; with
    ``ahead`` (else length 0) the coming step's largest squared displacement (1,), m^2; with
    ``wall_gap`` (else length 0) whether each wall slot conducts (N, W) bool: it touches, or its
    surface gap is at most ``wall_gap`` times the particle's diameter
    (:meth:`drumheat.mechanics.forces.ContactForces.wall_gap_mask`, the same test); with
    ``drift`` (else None) the positions, velocities and spins after the step's kicks and drift
    ``(pos, vel, omega)``, updated in place; with ``steps`` (else None) ``counted`` as above.
    """
    target = load()
    dtype = jnp.dtype(pos.dtype)
    if dtype not in (jnp.float32, jnp.float64):
        dtype = jnp.dtype(jnp.float32)
    n, dim = pos.shape
    m = idx.shape[1]
    nw = wall_spring.shape[1]
    sd = jax.ShapeDtypeStruct
    wshape = (n, 3) if dim == 3 else (n,)
    md = m if details else 0
    outs = [sd((n, dim), dtype), sd(wshape, dtype), sd((m, dim), dtype), sd((md,), dtype),
            sd((md,), dtype), sd((md,), dtype), sd((n, nw, dim), dtype), sd((n, nw), dtype),
            sd((n, nw), dtype), sd((1,), dtype)]
    if conduction_law is None:
        law, temperature = -1, jnp.zeros((0,), jnp.float64)
    else:
        from drumheat.mechanics.conduction import LAWS

        law = LAWS.index(conduction_law)
    outs.append(sd((temperature.shape[0],), jnp.float64))
    outs.append(sd((m,), jnp.bool_))
    fh = wall_distance_before is not None
    kp, kw = _rows(dim)
    outs += [sd((m, kp) if fh else (0,), dtype), sd((n * nw, kw) if fh else (0,), dtype),
             sd((3,), jnp.float64), sd((1,) if ahead is not None else (0,), dtype),
             sd((n, nw) if wall_gap is not None else (0,), jnp.bool_)]
    outs += [sd((n, dim) if drift is not None else (0,), dtype),
             sd((n, dim) if drift is not None else (0,), dtype),
             sd(wshape if drift is not None else (0,), dtype)]
    runs = steps is not None
    if runs and (drift is None or ahead is None or (nw and wall_gap is None)):
        raise ValueError("a run of steps in the call takes the drift, the skin test and the "
                         "wall slots' conduction flags")
    outs += [sd((m,) if runs else (0,), jnp.int32), sd((n * nw,) if runs else (0,), jnp.int32),
             sd((1,) if runs else (0,), jnp.int32)]
    wd0 = wall_distance_before if fh else jnp.zeros((0,))
    body = jnp.zeros((0,)) if body_force is None else body_force
    consts, ref = (jnp.zeros((0,)), jnp.zeros((0,))) if ahead is None else ahead
    shell = jnp.zeros((0,)) if shell is None else np.asarray(shell, dtype)
    none = jnp.zeros((0,))
    kick, f_before, t_before = (none, none, none) if drift is None else drift
    c = lambda a: jnp.asarray(a).astype(dtype)  # noqa: E731
    # springs updated in place: input 8 -> output 2 (pairs), input 12 -> output 6 (walls); with
    # the drift the positions, velocities and spins (inputs 0-2 -> outputs 17-19) and the forces
    # and torques, which the loop reads before it sums the new ones (24, 25 -> 0, 1): a loop's
    # carry is then updated in place, without XLA's copies of each
    aliases = {8: 2, 12: 6} | ({0: 17, 1: 18, 2: 19, 24: 0, 25: 1} if drift is not None else {})
    out = jax.ffi.ffi_call(target, outs, input_output_aliases=aliases)(
        c(pos), c(vel), c(omega).reshape(wshape), c(radius), c(mass), c(inertia),
        jnp.asarray(ptype).astype(jnp.int32), idx.astype(jnp.int32), c(spring),
        c(wall_distance), c(wall_normal), c(wall_velocity), c(wall_spring), c(tables_pp),
        c(tables_pw), c(wall_omega), temperature.astype(jnp.float64), c(wd0),
        _order_arg(order), c(body), c(consts), c(ref), c(shell), c(kick), c(f_before),
        c(t_before).reshape(wshape if drift is not None else (0,)),
        jnp.zeros((0,), dtype) if steps is None else jnp.stack([c(v) for v in steps]),
        dt=np.float64(dt), L=np.float64(periodic_length or 0.0), law=np.int32(law),
        h=np.float64(conduction_h), tol=np.float64(gap_tolerance),
        rot=np.int32(bool(rotation)), fh=np.int32(fh), cgap=np.float64(pair_gap),
        wgap=np.float64(wall_gap or 0.0))
    return (*out[:17], tuple(out[17:20]) if drift is not None else None,
            tuple(out[20:]) if runs else None)


def skin_test_constants(dt, inv_mass, periodic_length, lo, dtype):
    """The constants of :func:`contacts`' skin test (``ahead``) as the loop takes them:
    ``c = (dt / 2) (1 / m)`` (the product XLA folds the integrator's ``dt/2 F (1/m)`` into),
    dt, the period L of the last axis (0: none) and its reciprocal, and the box's lower corner
    ``lo`` (the neighbour list's frame), in ``dtype``."""
    one = lambda v: np.asarray(v, dtype)  # noqa: E731  a constant as XLA holds it
    L = one(periodic_length or 0.0)
    vals = [_half_kick(dt, inv_mass, dtype), one(dt), L, one(1.0) / L if L else one(0.0),
            *np.asarray(lo, dtype)]
    return to_device(np.array(vals, dtype))


def _half_kick(dt, inverse, dtype):
    """``(dt / 2) (1 / m)`` (or ``1 / I``) in ``dtype``: the one constant XLA folds the
    integrator's half-kick ``dt/2 F (1/m)`` into, as the loop takes it."""
    return np.asarray(0.5 * dt, dtype) * np.asarray(inverse, dtype)


def drift_constants(aux, dt, inv_mass, inv_inertia, periodic_length, dtype):
    """The constants of :func:`contacts`' kicks and drift (``drift``) as the loop takes them:
    the pending half-kick's factor ``aux`` (0 or 1, traced), ``c = (dt / 2) (1 / m)`` and
    ``c_I = (dt / 2) (1 / I)`` (the products XLA folds the integrator's ``dt/2 F (1/m)`` and
    ``dt/2 M (1/I)`` into), dt and the period L of the last axis (0: none), in ``dtype``."""
    rest = np.array([_half_kick(dt, inv_mass, dtype), _half_kick(dt, inv_inertia, dtype),
                     np.asarray(dt, dtype), np.asarray(periodic_length or 0.0, dtype)], dtype)
    return jnp.concatenate([jnp.asarray(aux, dtype).reshape(1), jnp.asarray(rest)])


def _order_arg(order):
    """The cell order as the library takes it: (N,) int32, or length 0 for none."""
    return jnp.zeros((0,), jnp.int32) if order is None else jnp.asarray(order, jnp.int32)


def contact_heat(vel, omega, idx, pair_rows, wall_rows, wall_velocity, wall_omega, dt,
                 conductivity=None, wall_conductivity=0.0, order=None):
    """Friction heat, the second pass: each contact's loss
    ``D = -dt (F . u + M_r . w_rel) - (U_new - U_old)`` at the full-step velocities ``vel``
    (N, D) and spins ``omega`` from the rows of :func:`contacts` (``pair_rows``, ``wall_rows``;
    ``wall_velocity`` (N, W, D) and ``wall_omega`` (W,) as given to it), split between the
    partners: ``k_A / (k_A + k_B)`` with the particles' ``conductivity`` (N,) and the walls'
    ``wall_conductivity``, or half and half (``conductivity`` None), as
    :func:`drumheat.mechanics.dissipation.step_heat` does. ``order``: the cell order given to
    :func:`contacts` (its threads then take the same ranges of pairs), or None.

    Returns ``(particle, sums)``: the heat into each particle (N,) and ``(walls, all)`` (2,),
    J, float64.
    """
    dtype = jnp.dtype(vel.dtype)
    n, dim = vel.shape
    c = lambda a: jnp.asarray(a).astype(dtype)  # noqa: E731
    k = (jnp.zeros((0,), jnp.float64) if conductivity is None
         else jnp.asarray(conductivity, jnp.float64))
    sd = jax.ShapeDtypeStruct
    return jax.ffi.ffi_call(HEAT_TARGET, [sd((n,), jnp.float64), sd((2,), jnp.float64)])(
        vel, c(omega).reshape((n, 3) if dim == 3 else (n,)), idx.astype(jnp.int32),
        pair_rows, wall_rows, c(wall_velocity), c(wall_omega), k,
        _order_arg(order),
        dt=np.float64(dt), kw=np.float64(wall_conductivity))


def count_conduction(T, diameter, alpha, idx, counts, dt: float, h: float):
    """The contact conduction of a coupled thermal step in one C++ pass (``CountConduction``
    of ``contact_kernel.cc``): the heat flow into each particle, W, (N,) float64,

        Q_i = sum over the slots k of g_k (c_k dt / h) (T_j - T_i), added at i, taken from j,

    with ``g = alpha pi min(r_i, r_j)^2`` (the ``"projected"`` law of
    :mod:`drumheat.mechanics.conduction`, which is
    :class:`drumheat.thermal.contact.ContactConduction`'s ``alpha_pp A_p`` with
    ``A_p = pi d^2 / 4`` of the smaller sphere, weigler-thermal-dem.md eq. [2.7]) and
    ``c dt / h`` the slot's contact-time fraction of the thermal step
    (:attr:`drumheat.thermal.network.ContactNetwork.pair_unit`). The sums take the slots in
    their order, both ends of a slot at once, where the JAX pair sum adds them block by block:
    the two differ by round-off.

    Args:
      T: temperatures (N,), K; diameter: (N,), m; alpha: alpha_pp, W/(m^2 K), a scalar.
      idx: the slots' particles (2, M), padding index N (where it is a neighbour list's, XLA
        hands the list itself); counts: (M,) the DEM steps each slot conducted (0: none, as
        for every padding slot).
      dt: the DEM step, s; h: the thermal step, s.

    Not differentiable by itself: :func:`drumheat.thermal.network.native_pair_sum` gives it
    the derivatives of the JAX sum.
    """
    load()
    f64 = jnp.float64
    T = jnp.asarray(T, f64)
    out = jax.ShapeDtypeStruct(T.shape, f64)
    return jax.ffi.ffi_call(COUNT_CONDUCTION_TARGET, out, vmap_method="sequential")(
        T, jnp.asarray(diameter, f64), jnp.reshape(jnp.asarray(alpha, f64), (1,)),
        jnp.asarray(idx, jnp.int32), jnp.asarray(counts, jnp.int32),
        dt=np.float64(dt), h=np.float64(h))


def neighbor_pairs(position, old_idx, capacity: int, cells, cell_size, cutoff: float,
                   periodic_length, cell_capacity: int, ranked: bool = False):
    """A neighbour rebuild in one C++ pass (``neighbor_kernel.cc``): the pairs of
    :meth:`drumheat.mechanics.neighbors.CellGrid.build` in the order of
    :func:`~drumheat.mechanics.neighbors.sort_pairs` (canonical, or with ``ranked`` grouped in
    the cell order), pair for pair, and where each came from.

    Args:
      position: box-frame positions (N, D), float32 or float64 (the arithmetic of the JAX
        build in that dtype); old_idx: the pairs (2, M_old) the data come from.
      capacity: pair slots M of the new list; cells, cell_size: the grid (per axis);
        cutoff: pair cutoff, m; periodic_length: period of the last axis or None;
        cell_capacity: particles one cell may hold (as the JAX build: a pair whose smaller
        index lies beyond it in its cell is not listed; the caller flags the overflow).
      ranked: the pairs grouped by their first particle in the cell order (``order``), as
        ``sort_pairs(..., order)``; else in canonical order.
    Returns ``(idx (2, M) int32 padded with N, source (M,) int32: the old slot of each new pair
    or -1, pairs found, fullest cell, order (N,) int32: the particles in the order of their
    cells, as :meth:`~drumheat.mechanics.neighbors.CellGrid.order`)``.
    """
    load()
    n, dim = position.shape
    cells = tuple(int(c) for c in cells) + (1,) * (3 - len(cells))
    size = tuple(float(s) for s in cell_size) + (1.0,) * (3 - len(cell_size))
    i32 = jnp.int32
    sd = jax.ShapeDtypeStruct
    outs = [sd((2, int(capacity)), i32), sd((int(capacity),), i32), sd((1,), i32), sd((1,), i32),
            sd((n,), i32)]
    # the new list in the old one's buffer where it has the same capacity (a rebuild; XLA
    # copies the old list first where it is still read later)
    alias = {1: 0} if tuple(old_idx.shape) == (2, int(capacity)) else {}
    idx, src, total, fullest, order = jax.ffi.ffi_call(NEIGHBOR_TARGET, outs,
                                                       input_output_aliases=alias)(
        position, old_idx.astype(i32), n0=np.int64(cells[0]), n1=np.int64(cells[1]),
        n2=np.int64(cells[2]), s0=np.float64(size[0]), s1=np.float64(size[1]),
        s2=np.float64(size[2]), cut2=np.float64(float(cutoff) ** 2),
        L=np.float64(periodic_length or 0.0), cap=np.int64(cell_capacity),
        ranked=np.int32(bool(ranked)))
    return idx, src, total[0], fullest[0], order


def take_pair_data_in_place(data, source):
    """:func:`drumheat.mechanics.neighbors.take_pair_data` in one C++ pass that writes the
    result into the buffer of ``data`` (an XLA alias; ``neighbor_kernel.cc``, ``TakePairs``):
    row k of the result is row ``source[k]`` of ``data``, zeros where ``source[k] < 0``, the
    same bits as the JAX gather. Where ``data`` dies in the call (the loop's springs and
    contact times at a rebuild), a rebuild then holds one column of scratch (M words) beside
    the list instead of a second copy of every per-pair array (docs/performance.md, Memory).

    Args:
      data: per-pair data (M, ...) of any dtype of 1, 2, 4 or 8 bytes.
      source: (M,) int32 from :func:`neighbor_pairs`, the old slot of each new pair or -1; the
        old and the new list have the same capacity M.
    """
    load()
    data = jnp.asarray(data)
    if source.shape != data.shape[:1]:
        raise ValueError(f"take_pair_data_in_place: {source.shape[0]} sources for "
                         f"{data.shape[0]} rows; the lists must have one capacity")
    out = jax.ShapeDtypeStruct(data.shape, data.dtype)
    return jax.ffi.ffi_call(TAKE_TARGET, out, input_output_aliases={1: 0})(
        source.astype(jnp.int32), data)

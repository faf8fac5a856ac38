"""The built-in 3D drum (glass-drum-3d, the LIGGGHTS benchmark drum): it loads with the
benchmark's set-up, and a small slice of it runs, heats from the wall and keeps its energy."""

import re

import jax.numpy as jnp
import pytest

import drumheat as dh
from drumheat.mechanics import cpu_kernel
from drumheat.motion import make_motion


def test_scene_is_the_benchmark_drum():
    s = dh.load_scene("glass-drum-3d")
    assert s.dim == 3 and s.n_particles == 2000
    assert s.drum.diameter == 0.25 and s.drum.rpm == 9.55 and s.drum.depth == 0.052
    assert s.dem.stiffness == 1.0e5 and s.dem.friction == 0.5 and s.dem.restitution == 0.5
    # the documented N knob keeps the fill level: depth = N x 2.6e-5 m
    big = s.replace({"groups.0.count": 10000, "drum.depth": 0.26})
    assert big.n_particles / big.drum.depth == pytest.approx(s.n_particles / s.drum.depth)


def test_a_small_slice_runs_and_heats():
    s = dh.load_scene("glass-drum-3d", {
        "groups.0.count": 150, "drum.depth": 0.026, "run.duration": 0.02,
        "run.output_interval": 0.01, "dem.replay_after": None, "dem.record_interval": None,
        "dem.replay_cycle": None})
    res = dh.run(s, progress=False)
    assert res.summary["complete"] and res.summary["energy_balance_rel_error"] < 1e-10
    assert res.timeseries["Q_wall"].iloc[-1] > 0  # the poured bed lies on the hot wall
    assert res.trajectory.position.shape == (3, 150, 3)


def _computations(hlo: str) -> dict:
    """The computations of an HLO module's text: name -> its instruction lines."""
    comps, name = {}, None
    for line in hlo.splitlines():
        m = re.match(r"^(?:ENTRY )?%(\S+) \(", line)
        if m and line.rstrip().endswith("{"):
            name = m.group(1)
            comps[name] = []
        elif name is not None:
            comps[name].append(line)
    return comps


def _called(comps: dict, name: str, seen: set) -> set:
    """``name`` and every computation it calls (fusions, conditionals, calls, loops)."""
    if name in seen or name not in comps:
        return seen
    seen.add(name)
    for line in comps[name]:
        callees = re.findall(r"(?:calls|to_apply|body|condition)=%([\w.\-]+)", line)
        for group in re.findall(r"branch_computations=\{([^}]*)\}", line):
            callees += re.findall(r"%([\w.\-]+)", group)
        for callee in callees:
            _called(comps, callee, seen)
    return seen


@pytest.mark.skipif(not cpu_kernel.available()[0], reason="C++ contact kernel unavailable")
def test_the_step_loop_copies_no_pair_buffer():
    """The scene's compiled chunk (C++ contact loop, as dem.contact_backend = "auto" takes it
    on a CPU) runs its steps between neighbour rebuilds in an inner loop that copies no
    pair-sized array (neighbour indices, springs, contact times): the issue's "no per-step
    copies of pair buffers". XLA copies them where a per-step lax.cond or a carried value
    forces it (docs/performance.md); the rebuild, once per run of steps, may."""
    s = dh.load_scene("glass-drum-3d", {"groups.0.count": 150, "drum.depth": 0.026,
                                        "dem.contact_backend": "cpu"})
    motion = make_motion(s)
    state = motion.initial_state()
    m = state.nbrs.idx.shape[1]
    assert m not in (motion.n, 3 * motion.n)  # pair-sized arrays are told by their length
    hlo = motion.dem._run_steps.lower(state, jnp.asarray(10, jnp.int32)).compile().as_text()
    comps = _computations(hlo)
    bodies = [b for lines in comps.values() for line in lines
              for b in re.findall(r"body=%([\w.\-]+)", line)]
    inner = [b for b in bodies
             if not any("body=%" in line for c in _called(comps, b, set()) for line in comps[c])]
    assert inner, "no innermost loop found in the compiled chunk"
    for body in inner:
        copies = [line.strip() for c in _called(comps, body, set()) for line in comps[c]
                  if " copy(" in line and re.search(rf"\b{m}\b", line.split(" copy(")[0])]
        assert not copies, copies


def _custom_calls(backend: str) -> set:
    """The custom-call targets in the scene's chunk (``DEM._run_steps``: runs of steps between
    neighbour rebuilds, the rebuilds, the coupled heat) on ``backend``, lowered to StableHLO,
    before any platform's compiler has seen it."""
    s = dh.load_scene("glass-drum-3d", {"groups.0.count": 150, "drum.depth": 0.026,
                                        "dem.contact_backend": backend})
    motion = make_motion(s)
    assert motion.contact_backend().backend == backend
    text = motion.dem._run_steps.lower(motion.initial_state(),
                                       jnp.asarray(10, jnp.int32)).as_text()
    return set(re.findall(r"custom_call @([\w$.]+)", text))


def test_the_jax_chunk_has_no_host_round_trip():
    """On the JAX backend (what a GPU runs: the C++ loop is the CPU's) the scene's whole chunk
    is XLA operations: no host callback and no native call in it, so on a GPU its steps,
    rebuilds and thermal steps stay on the device and the host waits once per chunk, not per
    step (issue 17: "nothing that would be slow on a GPU: host round-trips per step"). The C++
    backend's chunk, which does call out, shows that the check sees a call."""
    assert _custom_calls("jax") == set()
    if cpu_kernel.available()[0]:
        assert _custom_calls("cpu")  # the C++ contact loop is a custom call

"""The programs a run compiles: drumheat's own compiled functions, no eager jnp operations.

Every program XLA compiles stays in memory for the life of the process (on XLA:CPU host
memory for every program, a single operation's too), and an eager ``jnp`` operation
is one program per operation, shape and dtype (``jnp.asarray`` of a numpy array too:
``jit(stage)``); docs/performance.md, "Programs that stay in memory". Set-up code builds its
arrays with numpy and puts them on the device with :func:`drumheat.devices.to_device`, and
host-side work on device arrays runs as one compiled function.
"""

import contextlib
import logging
import re

import jax
import jax.numpy as jnp
import numpy as np
import pytest

import drumheat as dh
from drumheat.devices import device_copy, to_device

COMPILED = re.compile(r"Finished XLA compilation of jit\((.+)\) in ")

#: the compiled functions of drumheat that a run of glass-drum-3d (pour, coupled DEM with its
#: recording, cyclic replay, result) asks for, on either contact backend
RUN_PROGRAMS = {
    # set-up: the thermal model, the pour, the neighbour lists, the first forces
    "_spheres", "_fullest_network_limit", "_distance", "_wrapped", "_to_box",
    "_cpu_count_program", "_cpu_first_list", "_fullest_cell", "_count_pairs", "_build",
    "_first_list", "rest_forces", "<unnamed function>", "energies",
    # the chunks of the DEM and of the replay, and the host-side work between them
    "run_steps", "chunk_start", "_chunk_diagnostics", "particle_mechanics", "mean_contacts",
    "recorded_times", "_replay_steps",
    # the result
    "alpha_overall",
}


@contextlib.contextmanager
def compiled_programs():
    """Collect the names of the programs XLA compiles inside the block (a list)."""
    names = []

    class Collect(logging.Handler):
        def emit(self, record):
            m = COMPILED.match(record.getMessage())
            if m:
                names.append(m.group(1))

    handler, logger = Collect(logging.DEBUG), logging.getLogger("jax")
    level = logger.level
    logger.addHandler(handler)
    logger.setLevel(logging.DEBUG)
    jax.config.update("jax_log_compiles", True)
    try:
        yield names
    finally:
        jax.config.update("jax_log_compiles", False)
        logger.removeHandler(handler)
        logger.setLevel(level)


@pytest.mark.parametrize("x, dtype", [
    (np.arange(7.0), None), (np.arange(7), jnp.int32), ([1.5, 2.5], float),
    (np.ones((3, 4), np.float32), None), (np.ones((2, 3)), jnp.float32), (3.0, jnp.float64),
    (0, jnp.int32), (np.array([True, False]), jnp.float64)])
def test_to_device_gives_the_array_of_jnp_asarray_without_a_program(x, dtype):
    expected = jnp.asarray(x, dtype)
    with compiled_programs() as names:
        got = to_device(x, dtype)
        copy = device_copy(got)
    assert names == []
    assert got.dtype == expected.dtype and got.shape == expected.shape
    np.testing.assert_array_equal(np.asarray(got), np.asarray(expected))
    assert copy.unsafe_buffer_pointer() != got.unsafe_buffer_pointer()
    np.testing.assert_array_equal(np.asarray(copy), np.asarray(got))


def test_to_device_passes_tracers_and_keeps_arrays():
    a = jnp.arange(3.0)
    assert to_device(a) is a and to_device(a, jnp.float64) is a
    np.testing.assert_array_equal(to_device(2.0, ndmin=1), [2.0])
    # inside a trace, and a list holding a tracer: jnp.array's result, differentiable
    f = lambda t: jnp.sum(to_device([t, 2.0 * t], float, ndmin=1) ** 2)  # noqa: E731
    assert float(jax.jit(f)(3.0)) == 45.0
    assert float(jax.grad(f)(3.0)) == pytest.approx(30.0, rel=1e-15)
    assert jax.jit(lambda t: to_device(t, jnp.float32))(a).dtype == jnp.float32


@pytest.mark.parametrize("backend", ["auto", "jax"])
def test_a_run_compiles_only_drumheat_programs(backend):
    """A short run of the built-in 3D drum with its recording and replay (the phases of a
    user's run) compiles drumheat's compiled functions and nothing else, on the backend
    ``auto`` takes (the C++ loop where it builds) and on the JAX kernel. JAX's caches are
    cleared first, so that programs this process compiled for earlier tests are compiled
    (and seen) again."""
    s = dh.load_scene("glass-drum-3d", {
        "groups.0.count": 150, "drum.depth": 0.026, "run.duration": 0.03,
        "run.output_interval": 0.01, "dem.record_interval": 0.005, "dem.replay_after": 0.02,
        "dem.replay_cycle": 0.01, "dem.contact_backend": backend})
    jax.clear_caches()
    with compiled_programs() as names:
        res = dh.run(s, progress=False)
    assert res.summary["complete"]
    assert "run_steps" in names and "_replay_steps" in names  # the log was read
    unexpected = sorted(set(names) - RUN_PROGRAMS)
    assert not unexpected, (
        f"the run compiled programs that are not drumheat's compiled functions: {unexpected}. "
        "An eager jnp operation compiles a program per operation, shape and dtype, each "
        "kept in memory: build host arrays with numpy and drumheat.devices.to_device, run "
        "host-side work on device arrays as one jax.jit function (and name it here)")

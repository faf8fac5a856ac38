"""The run loop, ensembles, sharding, the compile cache, the host allocator's threshold and the
progress bar."""

from drumheat.runner.loop import run, simulate, trace  # noqa: F401

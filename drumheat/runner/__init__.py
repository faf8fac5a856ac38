"""The run loop, ensembles, sharding, the compile cache and the progress bar."""

from drumheat.runner.loop import run, simulate, trace  # noqa: F401

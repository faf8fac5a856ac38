"""The run loop, ensembles, sharding, the compile cache and the progress bar."""

from drumheat.runner.loop import Result, energy_balance, make_motion, make_result, run  # noqa: F401

"""The version of drumheat (one place; ``drumheat.__version__`` re-exports it)."""

# dev1: the contact-time accumulators of the coupled heat fold at the thermal steps, so a
# checkpoint of dev0 would be read wrongly: its version refuses it
# dev2: a coupled run that records no contacts carries no recording accumulators (a state of
# another layout): a checkpoint of dev1 is refused
# dev3: the coupled heat's contact times are whole DEM steps (int32) instead of float64
# seconds: a checkpoint of dev2 is refused
__version__ = "0.2.0.dev3"

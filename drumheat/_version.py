"""The version of drumheat (one place; ``drumheat.__version__`` re-exports it)."""

# dev1: the contact-time accumulators of the coupled heat fold at the thermal steps, so a
# checkpoint of dev0 would be read wrongly: its version refuses it
__version__ = "0.2.0.dev1"

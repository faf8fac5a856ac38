import os

os.environ.setdefault("MPLBACKEND", "Agg")

import drumheat  # noqa: E402,F401  (enables float64)

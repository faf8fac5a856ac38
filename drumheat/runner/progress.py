"""Progress bar over simulated time, with ETA (tqdm), shown for runs longer than a moment."""

from __future__ import annotations

import sys


class SimProgress:
    """Context manager: ``with SimProgress(duration, enabled) as p: p.update_to(t)``.

    The bar appears only after ``delay`` seconds, so short runs stay quiet. It shows the
    simulated time; its percentage and ETA follow ``work(t)``, the cumulative cost of reaching
    simulated time ``t`` (s from the start; default ``t`` itself), so that a run whose phases
    cost differently per simulated second (DEM, then a cheap replay) gets an honest ETA.
    """

    def __init__(self, duration: float, enabled: bool | None = True, desc: str = "simulating",
                 delay: float = 2.0, work=None):
        self.duration = float(duration)
        self.enabled = True if enabled is None else bool(enabled)
        self.desc, self.delay = desc, delay
        self.work = work if work is not None else (lambda t: t)
        self.bar = None
        self._t = 0.0

    def __enter__(self):
        if self.enabled:
            try:  # a notebook widget bar if ipywidgets is there, else the text bar
                import ipywidgets  # noqa: F401
                from tqdm.auto import tqdm
            except ImportError:
                from tqdm.std import tqdm
            # a terminal redraws one line; a log file (CI, nohup) gets a line per refresh, so
            # refresh it rarely there
            interactive = getattr(sys.stderr, "isatty", lambda: False)()
            self.bar = tqdm(total=float(self.work(self.duration)), desc=self.desc,
                            delay=self.delay, file=sys.stderr, dynamic_ncols=True,
                            mininterval=0.5 if interactive else 30.0,
                            bar_format="{desc}: {percentage:3.0f}%|{bar}| {postfix} "
                                       "[{elapsed}<{remaining}]")
            self.bar.set_postfix_str(self._clock(0.0), refresh=False)
        return self

    def _clock(self, t: float) -> str:
        return f"t = {t:.4g} / {self.duration:.4g} s"

    def update_to(self, t: float) -> None:
        """Report that the simulation reached time ``t`` (s)."""
        if self.bar is not None:
            self.bar.set_postfix_str(self._clock(float(t)), refresh=False)
            self.bar.update(float(self.work(float(t))) - float(self.work(self._t)))
        self._t = float(t)

    def note(self, text: str) -> None:
        """Show ``text`` beside the simulated time until the next :meth:`update_to` (host work
        between chunks that takes a while, e.g. the switch to a replay)."""
        if self.bar is not None:
            self.bar.set_postfix_str(f"{self._clock(self._t)}, {text}", refresh=True)

    def __exit__(self, *exc):
        if self.bar is not None:
            self.bar.close()
        return False

"""What the benchmark scripts report beside each timing: the machine's load and CPU steal."""

from __future__ import annotations

import os
from pathlib import Path


def load():
    return os.getloadavg()[0]


def cpu_ticks():
    """(steal, total) CPU ticks of the machine from /proc/stat (None off Linux)."""
    try:
        f = [int(v) for v in Path("/proc/stat").read_text().split("\n")[0].split()[1:]]
    except (OSError, ValueError):
        return None
    return f[7], sum(f)


def steal_percent(t0, t1):
    """Share of CPU time the hypervisor gave to other guests between two cpu_ticks(), %.

    On a shared virtual machine this, not the load average, tells a slow timing: on the
    development machine the same setting ran up to 2x slower in runs with much steal than in
    runs with almost none.
    """
    if t0 is None or t1 is None or t1[1] == t0[1]:
        return float("nan")
    return 100.0 * (t1[0] - t0[0]) / (t1[1] - t0[1])


def print_table(header, rows, formats) -> None:
    """A Markdown table: ``header`` (column names), ``rows`` (tuples), ``formats`` (one format
    spec per column, e.g. ``".1f"``)."""
    print("| " + " | ".join(header) + " |")
    print("|" + "---|" * len(header))
    for r in rows:
        print("| " + " | ".join(format(v, f) for v, f in zip(r, formats)) + " |")

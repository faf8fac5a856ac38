"""Mechanical mixing time of the glass drums on three readings of the thesis' rule (issue 16).

weigler-thermal-dem.md section 11.2: two halves of 185 white and 185 red glass spheres piled
segregated in the 250 mm drum, rotated at 9.55 or 47.75 rpm; t_mech is where a trend line
through the white-red contact count "becomes horizontal". The count is the column
``interfraction_contacts`` of the built-in scenes ``weigler-glass-mixing-9.55`` / ``-47.75``
(contacts with the heat model's definition: overlap or a gap within
``heat.contact.gap_tolerance``). Three readings of the rule on the same data:

* ``horizontal``: a straight rising trend line that turns horizontal, the break fitted by least
  squares (:func:`drumheat.results.observe.mixing_time_horizontal`): the thesis' words read
  literally;
* ``95 %`` / ``99 %``: a saturating exponential fitted to the counts, t_mech where it has
  covered 95 % / 99 % of its rise (:func:`drumheat.results.observe.mechanical_mixing_time`, the
  digest's suggestion).

Usage::

    drumheat run weigler-glass-mixing-9.55 --out results/mix-9.55 --set run.duration=180
    drumheat run weigler-glass-mixing-47.75 --out results/mix-47.75 --set run.duration=120
    python scripts/weigler_mixing_time.py results/mix-9.55 results/mix-47.75 --figure docs/img/weigler_mixing.png
"""

from __future__ import annotations

import argparse
import json
from pathlib import Path

import numpy as np
import pandas as pd

from drumheat.results.observe import mechanical_mixing_time, mixing_time_horizontal


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    ap.add_argument("folders", nargs="+", type=Path, help="result folders of the mixing scenes")
    ap.add_argument("--figure", type=Path, default=None)
    args = ap.parse_args(argv)

    rows, curves = [], []
    for folder in args.folders:
        ts = pd.read_csv(folder / "timeseries.csv")
        summary = json.loads((folder / "summary.json").read_text())
        t, c = ts["t"].to_numpy(), ts["interfraction_contacts"].to_numpy()
        ok = np.isfinite(c)
        t, c = t[ok], c[ok]
        hor = mixing_time_horizontal(t, c)
        e95 = mechanical_mixing_time(t, c, 0.95)
        e99 = mechanical_mixing_time(t, c, 0.99)
        late = c[t >= t[-1] / 2]
        rows.append((summary["scene"], t[-1], hor, e95, e99, late.mean(), late.std(),
                     summary.get("wall_time_s")))
        curves.append((summary["scene"], t, c, hor, e95))

    print("| scene | run (s) | horizontal trend (s) | exponential 95 % (s) | exponential 99 % (s) "
          "| tau (s) | count, second half (mean +- sd) | slope of the rise (1/s) | wall time (s) |")
    print("|---|---|---|---|---|---|---|---|---|")
    for name, dur, hor, e95, e99, m, sd, wall in rows:
        print(f"| {name} | {dur:.0f} | {hor.time:.1f} | {e95.time:.1f} | {e99.time:.1f} | "
              f"{e95.tau:.1f} | {m:.1f} +- {sd:.1f} | {hor.slope:.2f} | {wall} |")

    if args.figure is not None:
        import matplotlib

        matplotlib.use("Agg")
        import matplotlib.pyplot as plt

        fig, axes = plt.subplots(1, len(curves), figsize=(5.5 * len(curves), 4.0), squeeze=False)
        for ax, (name, t, c, hor, e95) in zip(axes[0], curves):
            ax.plot(t, c, ".", ms=2, color="grey", label="white-red contacts")
            ax.plot(t, hor.trend(t), "k-", label=f"horizontal trend: {hor.time:.0f} s")
            ax.plot(t, e95.trend(t), "r--", label=f"exponential, 95 %: {e95.time:.0f} s")
            ax.axvline(hor.time, color="k", lw=0.8)
            ax.axvline(e95.time, color="r", lw=0.8, ls="--")
            ax.set(title=name, xlabel="t (s)", ylabel="inter-fraction contacts")
            ax.legend(fontsize=8)
            ax.grid(alpha=0.3)
        fig.tight_layout()
        args.figure.parent.mkdir(parents=True, exist_ok=True)
        fig.savefig(args.figure, dpi=120)
        print(f"figure: {args.figure}")
    return 0


if __name__ == "__main__":
    raise SystemExit(main())

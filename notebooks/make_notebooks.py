"""Write the example notebooks 01-03 (run: python notebooks/make_notebooks.py).

Each notebook is kept short (short durations, small grids) so that the test suite
(tests/test_notebooks.py) executes it in well under a minute on two cores.
"""

from pathlib import Path

import nbformat
from nbformat.v4 import new_code_cell, new_markdown_cell, new_notebook

HERE = Path(__file__).resolve().parent

NOTEBOOKS = {
    "01_quickstart.ipynb": [
        new_markdown_cell(
            "# drumheat quickstart\n\nLoad a built-in scene, run it, look at the curves. "
            "The scene is Weigler's resting-bed equalisation (35 cold + 35 warm aluminium "
            "spheres, `weigler-static`), shortened to 600 s here."),
        new_code_cell(
            "import drumheat as dh\n"
            "print(dh.builtin_scenes())\n"
            "scene = dh.load_scene('weigler-static', overrides={'run.duration': 600.0})\n"
            "result = dh.run(scene, progress=False)\n"
            "result.timeseries.head()"),
        new_code_cell(
            "ax = result.timeseries.plot(x='t', y=['T_mean:cold', 'T_mean:warm', 'T_mean'])\n"
            "ax.set_xlabel('t (s)'); ax.set_ylabel('T (K)')\n"
            "print('energy balance error:', result.summary['energy_balance_rel_error'])"),
        new_markdown_cell(
            "## Semi-discrete penetration model\n\n`weigler-glass-random`: 370 glass spheres "
            "heated through the wall, particles randomly re-distributed every t_R = 40 s "
            "(Weigler ch. 5.3). Shortened to 400 s."),
        new_code_cell(
            "rnd = dh.run(dh.load_scene('weigler-glass-random', {'run.duration': 400.0}), "
            "progress=False)\n"
            "ax = rnd.timeseries.plot(x='t', y='alpha_overall')\n"
            "ax.set_ylabel('alpha_overall (W/(m2 K))')\n"
            "rnd.timeseries.tail(3)"),
    ],
    "02_heat_loss_fit.ipynb": [
        new_markdown_cell(
            "# Fitting the heat-loss parameter (alpha A)_WK\n\n`drumheat.calibrate.fit` fits "
            "scene parameters by gradients of the whole simulation (jax.jacfwd through the run) "
            "with optax. The data here are the **synthetic** curves shipped with drumheat "
            "(generated with (alpha A)_WK = 2.5e-4 W/K and 0.15 K noise by "
            "`scripts/make_synthetic_data.py`)."),
        new_code_cell(
            "from importlib.resources import files\n"
            "import pandas as pd\n"
            "from drumheat.calibrate import Experiment, fit, CalibrationDataError\n"
            "data = files('drumheat') / 'data'\n"
            "# the heating curve only, to keep the notebook short; add the cooling curve as a\n"
            "# second Experiment('weigler-cooling', data / 'synthetic_cooling.csv')\n"
            "exps = [Experiment('weigler-heating', data / 'synthetic_heating.csv', name='heating')]\n"
            "res = fit(exps, params={'heat.loss.alphaA': 2.0e-4})\n"
            "print(res)\n"
            "res.table()"),
        new_code_cell("fig = res.plot()\nres.history"),
        new_markdown_cell("Unusable data are refused with a message, e.g. temperatures in "
                          "degrees Celsius:"),
        new_code_cell(
            "try:\n"
            "    fit('weigler-heating', pd.DataFrame({'t': [60.0, 120.0], 'T_mean': [27.0, 28.5]}),\n"
            "        ['heat.loss.alphaA'])\n"
            "except CalibrationDataError as err:\n"
            "    print(err)"),
    ],
    "03_lambda_bed_calibration.ipynb": [
        new_markdown_cell(
            "# Calibration line alpha_pp -> lambda_bed\n\nThe A7 procedure of Weigler (ch. 5.2): "
            "heat the resting packing of `weigler-glass-wall` through the wall at two alpha_pp, "
            "read lambda_bed off at the time where the slope of alpha_overall reaches -0.5 "
            "(else its inflection point). A coarse time grid keeps this notebook short; the "
            "script `scripts/calibrate_lambda_bed.py` uses the full one."),
        new_code_cell(
            "from drumheat.calibrate import calibrate_lambda_bed\n"
            "cal = calibrate_lambda_bed('weigler-glass-wall', [57.0, 114.0], n_times=80,\n"
            "                           rho_bed=1230.0, convention='A7')\n"
            "print('line: lambda_bed = %.5g alpha_pp + %.4g' % (cal.line.slope, cal.line.intercept))\n"
            "print('fixed-time proportionality ratio:', cal.proportional)\n"
            "cal.table()"),
        new_code_cell("fig = cal.plot()"),
        new_code_cell(
            "inv = cal.alpha_pp(0.9)   # Newton's method on the differentiable map\n"
            "inv"),
    ],
}


def main():
    for name, cells in NOTEBOOKS.items():
        nb = new_notebook(cells=cells, metadata={"kernelspec": {
            "name": "python3", "display_name": "Python 3", "language": "python"}})
        nbformat.write(nb, HERE / name)
        print("wrote", HERE / name)


if __name__ == "__main__":
    main()

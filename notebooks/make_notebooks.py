"""Write the example notebooks 01-05 (run: python notebooks/make_notebooks.py).

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
            "# Fitting the heat-loss parameter (alpha A)_WK\n\n`drumheat.analysis.calibrate.fit` fits "
            "scene parameters by gradients of the whole simulation (jax.jacfwd through the run) "
            "with optax. The data here are the **synthetic** curves shipped with drumheat "
            "(generated with (alpha A)_WK = 2.5e-4 W/K and 0.15 K noise by "
            "`scripts/make_synthetic_data.py`)."),
        new_code_cell(
            "from importlib.resources import files\n"
            "import pandas as pd\n"
            "from drumheat.analysis.calibrate import Experiment, fit, CalibrationDataError\n"
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
            "from drumheat.analysis.calibrate import calibrate_lambda_bed\n"
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
    "04_mixed_drum.ipynb": [
        new_markdown_cell(
            "# The mixed drum: coupled DEM, replay, animation\n\n"
            "`weigler-mixed` is Weigler's experiment 5: the 35 cold + 35 warm aluminium spheres "
            "of `weigler-static`, now in a drum turning at 12 rpm. The motion model `dem` "
            "simulates mechanics and heat together (soft-sphere DEM, one thermal step every "
            "`dem.thermal_substeps` mechanical steps) and records the contact network; after "
            "`dem.replay_after` seconds it continues by cyclic replay of the recorded contacts "
            "(no mechanics, see the docs page *Recorded-contact replay*).\n\n"
            "To run in about a minute on two cores this notebook shortens the scene: 120 s "
            "instead of 1800 s, one output per second, and only the first 5 s (one revolution) "
            "simulated with DEM instead of 10 s (two revolutions). Everything else is the "
            "built-in scene."),
        new_code_cell(
            "from pathlib import Path\n"
            "import matplotlib.pyplot as plt\n"
            "import drumheat as dh\n"
            "from drumheat.results import plot\n"
            "from drumheat.results.animate import animate\n"
            "\n"
            "short = {'run.duration': 120.0, 'run.output_interval': 1.0, 'dem.replay_after': 5.0}\n"
            "mixed = dh.run(dh.load_scene('weigler-mixed', short), progress=False)\n"
            "out = mixed.save('results/weigler-mixed-short')   # timeseries.csv, particles.npz, "
            "contacts.npz, PNGs\n"
            "print('written to', out)\n"
            "print('wall time %.1f s, energy balance error %.1e' % (\n"
            "    mixed.summary['wall_time_s'], mixed.summary['energy_balance_rel_error']))\n"
            "ts = mixed.timeseries\n"
            "# contacts between the fractions, counted while the DEM moves the particles\n"
            "dem_part = ts['t'] <= 5.0\n"
            "print('cold-warm contacts during the DEM phase:',\n"
            "      ts.loc[dem_part, 'interfraction_contacts'].tolist())\n"
            "ts[['t', 'T_mean', 'T_mean:cold', 'T_mean:warm']].iloc[::20]"),
        new_markdown_cell(
            "## Animation\n\n`drumheat.results.animate.animate` (or `drumheat animate RESULT_DIR` on "
            "the command line) writes one frame per output time from the result folder; "
            "`every=2` keeps every second output. The first 5 s are the DEM run itself; after "
            "that the frames show the recorded positions of the replayed revolution."),
        new_code_cell(
            "gif = animate(out, fps=10, every=2)\n"
            "print(gif, '%.1f MB' % (gif.stat().st_size / 1e6))\n"
            "from IPython.display import Image\n"
            "Image(filename=str(gif))"),
        new_markdown_cell(
            "One frame as a figure of its own (here the output at t = 60 s). After "
            "`dem.replay_after` the particles move through the recorded revolution again, so "
            "the positions at 60 s are those of the first revolution, when the two fractions "
            "were still in their halves (the figure's title says so); the temperatures are "
            "those at 60 s. The mixing itself shows in the first 5 s of the animation and in "
            "the contact counts above."),
        new_code_cell(
            "k = int(abs(mixed.t - 60.0).argmin())\n"
            "fig = plot.plot_snapshot(mixed, index=k)"),
        new_markdown_cell(
            "## Resting versus mixed\n\nThe same bed at rest (`weigler-static`) over the same "
            "120 s. In the resting bed the two fractions exchange heat only across the few "
            "contacts where the layers touch; turning the drum brings cold and warm spheres "
            "together (more contacts between the fractions), so the fraction means approach "
            "each other faster."),
        new_code_cell(
            "static = dh.run(dh.load_scene('weigler-static', {'run.duration': 120.0,\n"
            "                                                  'run.output_interval': 1.0}),\n"
            "                progress=False)\n"
            "fig, ax = plt.subplots(figsize=(7, 4.5))\n"
            "for res, style, label in ((mixed, '-', 'mixed, 12 rpm'), (static, '--', 'resting')):\n"
            "    ts = res.timeseries\n"
            "    for group, colour in (('cold', 'tab:blue'), ('warm', 'tab:red')):\n"
            "        ax.plot(ts['t'], ts[f'T_mean:{group}'] - 273.15, style, color=colour,\n"
            "                label=f'{group}, {label}')\n"
            "ax.set_xlabel('t (s)'); ax.set_ylabel('fraction mean temperature (°C)')\n"
            "ax.legend(); ax.grid(alpha=0.3)\n"
            "gap = lambda r: r.timeseries['T_mean:warm'] - r.timeseries['T_mean:cold']\n"
            "print('warm - cold after 120 s: mixed %.2f K, resting %.2f K'\n"
            "      % (gap(mixed).iloc[-1], gap(static).iloc[-1]))"),
    ],
    "05_effects.ipynb": [
        new_markdown_cell(
            "# Which effects matter? Advisor, radiation and internal conduction\n\n"
            "`drumheat.analysis.advisor.explain` (command line: `drumheat explain SCENE`) estimates, for "
            "a scene's start conditions, the heat flow of every effect per particle, included or "
            "not, and says which included ones could be dropped and which absent ones should be "
            "added; the Biot number tells whether the particles may be lumped."),
        new_code_cell(
            "from drumheat.analysis.advisor import explain\n"
            "print(explain('weigler-static').text())"),
        new_markdown_cell(
            "The resting aluminium bed: contact conduction dominates; convection and radiation "
            "are covered by the lumped loss `[heat.loss]`; Bi << 0.1, so lumped particles are "
            "right. A hot slag droplet in a dry slag granulator (Staltner 2018) is the "
            "opposite case:"),
        new_code_cell("print(explain('staltner-slag-particle').text())"),
        new_markdown_cell(
            "## The slag droplet\n\n`staltner-slag-particle` follows one droplet (d = 2 mm, "
            "1350 °C) through flight to the water-cooled wall (convection + radiation in the "
            "four-zone enclosure), wall contact (conduction into the wall) and the fall to the "
            "bed, with 150 radial shells (`[heat.internal]`). Other diameters: "
            "`overrides={'groups.0.diameter': 0.0005}`. Besides the standard files the run "
            "writes `phases.csv` and `radial_profiles.png`."),
        new_code_cell(
            "import pandas as pd\n"
            "import drumheat as dh\n"
            "from IPython.display import Image\n"
            "\n"
            "slag = dh.run('staltner-slag-particle', out='results/staltner-2mm', progress=False)\n"
            "phases = pd.read_csv('results/staltner-2mm/phases.csv')\n"
            "phases[['phase', 'name', 'duration_s', 'T_mean_degC', 'T_surface_K', 'T_centre_K',\n"
            "        'Q_gas_J', 'Q_radiation_J', 'Q_wall_J']]"),
        new_code_cell("Image(filename='results/staltner-2mm/radial_profiles.png')"),
        new_markdown_cell(
            "The centre is still at its initial 1350 °C when the droplet reaches the bed, while "
            "the surface cooled by more than 100 K in flight and far more in wall contact: this "
            "is what Bi ~ 1 means, and why a lumped particle would be wrong here.\n\n"
            "## Radiation switched off\n\nA scene is edited in Python like a record: "
            "`scene.replace({...})` changes values by their dotted keys, `scene.without(...)` "
            "switches an effect off by dropping its table, and both check the new scene as "
            "the TOML loader would (a misspelt key raises a `SceneError` naming it); "
            "`scene.save('mine.toml')` writes it for the command line (docs: *Build a scene "
            "in Python*)."),
        new_code_cell(
            "scene = dh.load_scene('staltner-slag-particle')\n"
            "no_rad_scene = scene.without('heat.radiation')\n"
            "print(scene.heat.radiation is not None, no_rad_scene.heat.radiation)\n"
            "no_rad = dh.run(no_rad_scene, progress=False)\n"
            "\n"
            "table = pd.DataFrame({\n"
            "    'with radiation': slag.timeseries.iloc[-1][['T_mean', 'T_surface', 'T_centre']],\n"
            "    'without radiation': no_rad.timeseries.iloc[-1][['T_mean', 'T_surface', 'T_centre']],\n"
            "})\n"
            "table['difference'] = table['without radiation'] - table['with radiation']\n"
            "print('at the end of the fall (K):')\n"
            "table"),
        new_code_cell(
            "import matplotlib.pyplot as plt\n"
            "fig, ax = plt.subplots(figsize=(7, 4.5))\n"
            "for res, style, label in ((slag, '-', 'with radiation'), (no_rad, '--', 'without')):\n"
            "    ts = res.timeseries\n"
            "    ax.plot(1e3 * ts['t'], ts['T_mean'] - 273.15, style, color='k', label=f'mean, {label}')\n"
            "    ax.plot(1e3 * ts['t'], ts['T_surface'] - 273.15, style, color='tab:red',\n"
            "            label=f'surface, {label}')\n"
            "ax.set_xlabel('t (ms)'); ax.set_ylabel('temperature (°C)'); ax.legend(); ax.grid(alpha=0.3)"),
        new_markdown_cell(
            "Radiation and convection are of similar size in flight (the advisor's table above; "
            "`Q_gas_J` and `Q_radiation_J` in the phase table), and the wall contact takes most "
            "of the heat (`Q_wall_J`). Without radiation the droplet lands warmer by the "
            "difference in the table above. The documentation pages *Convection*, *Radiation* "
            "and *Internal conduction* give the equations and sources."),
    ],
}


def main():
    for name, cells in NOTEBOOKS.items():
        for k, cell in enumerate(cells):  # stable ids: regenerating changes no unchanged cell
            cell["id"] = f"{Path(name).stem}-{k:02d}"
        nb = new_notebook(cells=cells, metadata={"kernelspec": {
            "name": "python3", "display_name": "Python 3", "language": "python"}})
        nbformat.write(nb, HERE / name)
        print("wrote", HERE / name)


if __name__ == "__main__":
    main()

"""Snakemake adapter: assemble the HTML report from the data on disk."""

import html
import json
import logging
from pathlib import Path

import h5py
import numpy as np

from fem.plots import plot_sweep_map
from surrogate.data import load_dataset
from surrogate.evaluate import compare_case, time_prediction
from surrogate.plots import plot_history
from surrogate.predict import Surrogate

logging.basicConfig(filename=snakemake.log[0], level=logging.INFO, force=True)

out = Path(snakemake.output.html)
out.parent.mkdir(parents=True, exist_ok=True)
ds = load_dataset(snakemake.input.dataset)
model = Surrogate.load(snakemake.input.model)
history = json.loads(Path(snakemake.input.history).read_text())
quality = json.loads(Path(snakemake.input.quality).read_text())


def table(header, rows):
    head = "".join(f"<th>{html.escape(str(h))}</th>" for h in header)
    body = "".join(
        "<tr>" + "".join(f"<td>{html.escape(str(c))}</td>" for c in row) + "</tr>" for row in rows
    )
    return f"<table><tr>{head}</tr>{body}</table>"


plot_history(history["history"], out.parent / "training_history.png", model.config.architecture)
with h5py.File(snakemake.input.dataset, "r") as h5:
    wall = h5["cases/wall_s"][...]
    steps = h5["cases/load_steps"][...]
plot_sweep_map(ds.C1, ds.phi, wall, out.parent / "sweep_cost.png", "FE solve wall time (s)",
               failed=~ds.converged, title="FE cost per case")

rows = []
for item in snakemake.params.clinical:
    try:
        case = ds.case_index(item["C1"], item["phi"], item.get("theta", 0.0))
    except KeyError:
        continue
    c = compare_case(model, ds, case)
    t = time_prediction(model, c["C1"], c["phi"], repeats=50)
    rows.append([item.get("label", c["case"]), f"{c['fe_mean_mm']:.2f}", f"[0, {c['fe_range_mm'][1]:.1f}]",
                 f"{c['surrogate_mean_mm']:.2f}", f"{c['rmse_mm']:.3f} ± {c['sd_mm']:.3f}",
                 f"{1e3 * t['median_s']:.3f}"])

page = f"""<!doctype html><html><head><meta charset="utf-8"><title>Breast gravity surrogate report</title>
<style>body{{font-family:sans-serif;max-width:1000px;margin:auto}}table{{border-collapse:collapse}}
td,th{{border:1px solid #999;padding:3px 8px;text-align:right}}</style></head><body>
<h1>Breast gravity loading: FE sweep and surrogate</h1>
<h2>Mesh</h2>
{table(["cells", "vertices", "volume (ml)", "min SICN", "min dihedral (deg)"],
       [[quality["cells"], quality["vertices"], f"{quality['volume_ml']:.0f}",
         f"{quality.get('min_minSICN', float('nan')):.3f}", f"{quality['min_dihedral_deg']:.1f}"]])}
<h2>FE sweep</h2>
<p>{int(ds.converged.sum())} of {len(ds.C1)} cases converged; load steps {int(steps.min())}-{int(steps.max())}.</p>
<img src="sweep_cost.png" alt="FE cost per case">
<h2>Surrogate ({model.config.architecture})</h2>
<p>Validation error {history['summary']['validation_error_mm']:.4f} mm after
{history['summary']['epochs']} epochs ({history['summary']['train_s']:.1f} s).</p>
<img src="training_history.png" alt="training history">
<h2>Clinical cases (paper Table 3)</h2>
{table(["case", "FE mean (mm)", "FE range (mm)", "surrogate mean (mm)", "RMSE ± SD (mm)", "prediction (ms)"], rows)}
</body></html>
"""
out.write_text(page)

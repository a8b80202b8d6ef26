"""Snakemake adapter: gather the speed-accuracy variants and mark their Pareto front.

Also the cheapest variant meeting the accuracy target.
"""

import json
import logging

from studies.fe_speed_accuracy import summarise_variants

logging.basicConfig(filename=snakemake.log[0], level=logging.INFO, force=True)

records = [json.load(open(path)) for path in snakemake.input]
summary = summarise_variants(records, target=snakemake.params.target)
summary["default_variant"] = snakemake.params.default_variant
with open(snakemake.output[0], "w") as fh:
    json.dump(summary, fh, indent=2, default=float)

"""Snakemake adapter: gather the speed-accuracy variants and mark their Pareto front.

Also the cheapest variant meeting the accuracy target.
"""

import logging

from studies.fe_speed_accuracy import VariantRecord, summarise_variants

logging.basicConfig(filename=snakemake.log[0], level=logging.INFO, force=True)

records = [VariantRecord.read(path) for path in snakemake.input]
summary = summarise_variants(
    records, target=snakemake.params.target, default_variant=snakemake.params.default_variant
)
summary.write(snakemake.output[0])

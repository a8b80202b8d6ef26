"""Snakemake adapter: gather the speed-accuracy variants and mark their Pareto front.

Also the cheapest variant meeting the accuracy target.
"""

from studies.fe_speed_accuracy import VariantRecord, summarise_variants
from studies.joblog import job_log

job_log(snakemake.log[0])

records = [VariantRecord.read(path) for path in snakemake.input]
summary = summarise_variants(
    records, target=snakemake.params.target, default_variant=snakemake.params.default_variant
)
summary.write(snakemake.output[0])

"""Snakemake adapter: gather the speed-accuracy variants and mark their Pareto front.

Also the cheapest variant meeting the accuracy target.
"""

from run.joblog import job_log
from studies.fe_study.fe_speed_accuracy import FEVariantRecord, summarise_fe_variants

job_log(snakemake.log[0])

records = [FEVariantRecord.read(path) for path in snakemake.input]
summary = summarise_fe_variants(
    records, target=snakemake.params.target, default_variant=snakemake.params.default_variant
)
summary.write(snakemake.output[0])

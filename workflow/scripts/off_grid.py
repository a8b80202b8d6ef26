"""Snakemake adapter: the surrogate against FE at random cases off the sweep's grid."""

from surrogate.runtime import configure_cpu

configure_cpu()

from run.joblog import job_log  # noqa: E402
from studies.surrogate_study.off_grid import evaluate_off_grid  # noqa: E402
from surrogate.predict import Surrogate  # noqa: E402

job_log(snakemake.log[0])

cases = list(zip(snakemake.input.summaries, snakemake.input.points, snakemake.input.fields,
                 strict=True))
evaluate_off_grid(Surrogate.load(snakemake.input.model), cases).write(snakemake.output[0])

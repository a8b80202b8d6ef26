"""Snakemake adapter: where the selected model warns over the range it was trained on."""

from surrogate.runtime import configure_cpu

configure_cpu()

from run.joblog import job_log  # noqa: E402
from studies.surrogate_study.warning_coverage import warning_coverage  # noqa: E402
from surrogate.predict import Surrogate  # noqa: E402

job_log(snakemake.log[0])

warning_coverage(Surrogate.load(snakemake.input.model)).write(snakemake.output[0])

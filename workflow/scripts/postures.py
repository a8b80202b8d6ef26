"""Snakemake adapter: the surrogate against FE in every clinical posture."""

from surrogate.runtime import configure_cpu

configure_cpu()

from run.joblog import job_log  # noqa: E402
from studies.surrogate_study.postures import evaluate_postures  # noqa: E402
from surrogate.predict import Surrogate  # noqa: E402

job_log(snakemake.log[0])

cases = [
    (name, in_sweep, summary, points, fields)
    for (name, in_sweep), summary, points, fields in zip(
        snakemake.params.postures, snakemake.input.summaries, snakemake.input.points,
        snakemake.input.fields, strict=True,
    )
]
evaluate_postures(Surrogate.load(snakemake.input.model), cases).write(snakemake.output[0])

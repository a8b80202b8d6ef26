"""Snakemake adapter: each held-out model on its test cases, the by-sample model beside it."""

from pathlib import Path

from surrogate.runtime import configure_cpu

configure_cpu()

from fem.dataset import read_dataset  # noqa: E402
from run.joblog import job_log  # noqa: E402
from studies.fe_study.stability_audit import without_unstable  # noqa: E402
from studies.surrogate_study.held_out import evaluate_held_out  # noqa: E402
from surrogate.predict import Surrogate  # noqa: E402

job_log(snakemake.log[0])

dataset = read_dataset(snakemake.input.dataset, nodes=True)  # the centroids, where it has them
dataset = without_unstable(dataset, snakemake.input.audit)  # no answer to test against there
models = {Path(path).parent.name.removeprefix("model_"): Surrogate.load(path)
          for path in snakemake.input.held_out}
evaluate_held_out(models, Surrogate.load(snakemake.input.model), dataset).write(snakemake.output[0])

"""Snakemake adapter: the surrogate's error on FE cases outside its training range."""

from surrogate.runtime import configure_cpu

configure_cpu()

from fem.dataset import read_dataset  # noqa: E402
from run.joblog import job_log  # noqa: E402
from studies.surrogate_study.surrogate_evaluation import Extrapolation, evaluate_extrapolation  # noqa: E402
from surrogate.predict import Surrogate  # noqa: E402

job_log(snakemake.log[0])

dataset = read_dataset(snakemake.input.dataset)
models = {"by_sample": Surrogate.load(snakemake.input.model),
          "by_case": Surrogate.load(snakemake.input.model_by_case)}
cases = list(zip(snakemake.input.summaries, snakemake.input.points, strict=True))
result = evaluate_extrapolation(models, dataset, cases)
Extrapolation.from_json(result).write(snakemake.output[0])

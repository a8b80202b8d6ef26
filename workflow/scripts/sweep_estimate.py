"""Snakemake adapter: the sweep's error estimate against the truth at held-out cases."""

from pathlib import Path

from surrogate.runtime import configure_cpu

configure_cpu()

from fem.dataset import read_dataset  # noqa: E402
from run.joblog import job_log  # noqa: E402
from studies.surrogate_study.off_grid import OffGridEvaluation  # noqa: E402
from studies.sweep.sweep_estimate import check_estimate  # noqa: E402
from surrogate.predict import Surrogate  # noqa: E402

job_log(snakemake.log[0])

models = {Path(path).parent.name.removeprefix("model_"): Surrogate.load(path)
          for path in snakemake.input.held_out}
check_estimate(read_dataset(snakemake.input.dataset), OffGridEvaluation.read(
    snakemake.input.off_grid), snakemake.input.off_grid_points, models).write(snakemake.output[0])

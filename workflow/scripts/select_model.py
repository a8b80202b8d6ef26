"""Snakemake adapter: the model used downstream, from the study's selected run.

With ``surrogate_study.refit`` the selected run's config is trained again on the same data and
its validation data too, for the epochs the run's validation chose
(:func:`surrogate.train.train_and_evaluate`'s ``refit_epochs``); otherwise the run is copied.
Either way the dataset's failed cases, and those whose FE state is unstable, are recorded with
it so that it warns where no FE solution backs it.
"""

import logging
from pathlib import Path

from surrogate.runtime import configure_cpu

configure_cpu(single_thread=snakemake.threads == 1)  # before JAX starts: one core per job

from fem.dataset import read_dataset  # noqa: E402
from run.joblog import job_log  # noqa: E402
from studies.fe_study.stability_audit import without_unstable  # noqa: E402
from studies.surrogate_study.architecture import (  # noqa: E402
    ArchitectureTable,
    copy_model,
    refit_model,
)
from surrogate.checkpoint import read_model_card  # noqa: E402
from surrogate.config import SurrogateConfig  # noqa: E402
from surrogate.structures import structure_for  # noqa: E402

job_log(snakemake.log[0])
log = logging.getLogger("select_model")

table = ArchitectureTable.read(snakemake.input.table)
run, folder = table.selected_run, Path(snakemake.output.model).parent
if snakemake.params.refit:
    config = SurrogateConfig.from_mapping(read_model_card(run)["config"])
    dataset = read_dataset(snakemake.input.dataset, nodes=structure_for(config).reads_nodes)
    result = refit_model(run, without_unstable(dataset, snakemake.input.audit), folder)
    log.info("selected %s: %s, trained again on %d cases for %d epochs in %.0f s",
             table.selected_architecture, run, result.train_cases.size, result.best_epoch,
             result.train_s)
else:
    copy_model(run, folder,
               dataset=without_unstable(read_dataset(snakemake.input.dataset),
                                        snakemake.input.audit))
    log.info("selected %s: %s", table.selected_architecture, run)

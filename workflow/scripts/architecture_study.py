"""Snakemake adapter: the architecture study's Table 2, the selection, one-core prediction times."""

import logging

from fem.sweep import clinical_cases
from run.joblog import job_log
from studies.surrogate_study.architecture import (
    ArchitectureTable,
    architecture_table,
    read_run,
    select_architecture,
)
from studies.surrogate_study.timing import time_on_one_core

job_log(snakemake.log[0])
log = logging.getLogger("architecture_study")

table = architecture_table(read_run(path) for path in snakemake.input.runs)
queries = [(c.C1, c.phi, c.theta) for c in clinical_cases(snakemake.params.clinical)] or [
    (1.0, 0.0, 0.0)
]
best_runs = {arch: row["best_run"] for arch, row in table["rows"].items()}
timing = time_on_one_core(list(best_runs.values()), queries, repeats=snakemake.params.repeats)
for arch, folder in best_runs.items():
    table["rows"][arch]["predict_one_core"] = timing["models"][folder]
table["timing"] = {k: v for k, v in timing.items() if k != "models"}
select_architecture(table, snakemake.params.budget_ms)
table.update(repeats=snakemake.params.study_repeats, repeat_within=snakemake.params.within)
ArchitectureTable.from_json(table).write(snakemake.output.table)
for arch, row in table["rows"].items():
    log.info(
        "%s: %.4f ± %.4f mm, %.0f ± %.0f s, predict %.3f ms",
        arch,
        row["validation_error_mm"]["mean"],
        row["validation_error_mm"]["sd"],
        row["train_s"]["mean"],
        row["train_s"]["sd"],
        row["predict_one_core"]["api"]["median_ms"],
    )
log.info("selected %s (%s)", table["selected_architecture"], table["selected_run"])

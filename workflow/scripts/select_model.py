"""Snakemake adapter: the model used downstream is the study's selected run, copied.

It is not retrained; the dataset's failed cases, and those whose FE state is unstable, are
recorded with it so that it warns where no FE solution backs it.
"""

import json
import logging
from pathlib import Path

from fem.dataset import read_dataset
from studies.architecture import copy_model
from studies.joblog import job_log
from studies.stability_audit import without_unstable

job_log(snakemake.log[0])

table = json.loads(Path(snakemake.input.table).read_text())
copy_model(table["selected_run"], Path(snakemake.output.model).parent,
           dataset=without_unstable(read_dataset(snakemake.input.dataset), snakemake.input.audit))
logging.getLogger("select_model").info(
    "selected %s: %s", table["selected_architecture"], table["selected_run"])

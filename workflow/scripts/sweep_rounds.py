"""Snakemake adapter: every round of the adaptive sweep in one record (fem.adaptive)."""

import json
from pathlib import Path

from fem.adaptive import RoundPlan, rounds_record
from studies.joblog import job_log

job_log(snakemake.log[0])

record = rounds_record([RoundPlan.read(path) for path in snakemake.input])
Path(snakemake.output[0]).write_text(json.dumps(record, indent=1) + "\n")

"""Snakemake adapter: write the HTML report and its figures (report.build)."""

from report.build import build_report
from run.joblog import job_log
from run.run_log import newest_log

job_log(snakemake.log[0])
inputs = dict(snakemake.input.items())
try:  # this run's own log, up to this job: its time by stage (not an input: it is the run's)
    inputs["run_log"] = newest_log(".")
except FileNotFoundError:
    pass
build_report(inputs, snakemake.output.html, snakemake.params.clinical,
             first=snakemake.params.first)

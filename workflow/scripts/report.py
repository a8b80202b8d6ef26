"""Snakemake adapter: write the HTML report and its figures (report.build)."""

from report.build import build_report
from studies.joblog import job_log

job_log(snakemake.log[0])
build_report(dict(snakemake.input.items()), snakemake.output.html, snakemake.params.clinical)

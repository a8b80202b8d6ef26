"""Snakemake adapter: write the HTML report and its figures (report.build)."""

import logging

from report.build import build_report

logging.basicConfig(filename=snakemake.log[0], level=logging.INFO, force=True)
build_report(dict(snakemake.input.items()), snakemake.output.html, snakemake.params.clinical)

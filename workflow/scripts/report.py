"""Snakemake adapter: write the HTML report and its figures (surrogate.report)."""

import logging

from surrogate.report import build_report

logging.basicConfig(filename=snakemake.log[0], level=logging.INFO, force=True)
build_report(dict(snakemake.input.items()), snakemake.output.html, snakemake.params.clinical)

"""Snakemake adapter: write the interactive 3D view (report.viewer)."""

from pathlib import Path

from surrogate.runtime import configure_cpu

configure_cpu()

from report.viewer import build_viewer  # noqa: E402
from studies.joblog import job_log  # noqa: E402

job_log(snakemake.log[0])
build_viewer(
    Path(snakemake.input.model).parent,
    snakemake.input.mesh,
    snakemake.input.dataset,
    snakemake.output.html,
    snakemake.params.clinical,
    snakemake.params.postures,
)

"""Snakemake adapter: write the interactive 3D view (report.viewer)."""

from pathlib import Path

from surrogate.runtime import configure_cpu

configure_cpu()

from fem.sweep import clinical_list  # noqa: E402
from report.viewer import build_viewer  # noqa: E402
from run.joblog import job_log  # noqa: E402
from studies.reference_state.tracking import TrackingResult  # noqa: E402

job_log(snakemake.log[0])
points = []  # each tracked set's points at their material (reference) positions
for path in snakemake.input.tracked:
    tracked = TrackingResult.read(path)
    points += [(f"{Path(path).stem}: {name}", xyz)
               for name, xyz in zip(tracked.names, tracked.reference, strict=True)]
build_viewer(
    Path(snakemake.input.model).parent,
    snakemake.input.mesh,
    snakemake.input.dataset,
    snakemake.output.html,
    clinical_list(snakemake.params.clinical),
    snakemake.params.postures,
    points,
    snakemake.params.start,
    snakemake.params.initial,
)

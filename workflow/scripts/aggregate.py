"""Snakemake adapter: gather all case files into one HDF5 dataset."""

from fem.aggregate import build_dataset
from fem.exceptions import DatasetError
from fem.splits import SplitFractions
from run.joblog import job_log
from run.workdir import mark_refused

job_log(snakemake.log[0])

cfg = snakemake.params.dataset
try:
    build_dataset(
        snakemake.input.summaries,
        snakemake.input.points,
        snakemake.output[0],
        split=SplitFractions(**cfg.get("split", {})),
        seed=int(cfg.get("seed", 0)),
        config=snakemake.params.provenance,
        test_cases=[(c["C1"], c["phi"], c.get("theta", 0.0)) for c in snakemake.params.clinical],
        mesh=snakemake.input.mesh,
        fields_paths=snakemake.input.fields,
    )
except DatasetError as err:  # the kept dataset stays out of date until the input is fixed
    mark_refused(snakemake.output[0], str(err))
    raise

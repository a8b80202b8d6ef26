"""Snakemake adapter: gather all case files into one HDF5 dataset."""

from fem.aggregate import build_dataset
from fem.exceptions import DatasetError
from fem.splits import DatasetSplit
from fem.sweep import clinical_cases
from run.joblog import job_log
from run.workdir import mark_refused

job_log(snakemake.log[0])

dataset = DatasetSplit.from_mapping(snakemake.params.dataset)
try:
    build_dataset(
        snakemake.input.summaries,
        snakemake.input.points,
        snakemake.output[0],
        split=dataset.fractions,
        seed=dataset.seed,
        config=snakemake.params.provenance,
        test_cases=clinical_cases(snakemake.params.clinical),
        mesh=snakemake.input.mesh,
        fields_paths=snakemake.input.fields,
    )
except DatasetError as err:  # the kept dataset stays out of date until the input is fixed
    mark_refused(snakemake.output[0], str(err))
    raise

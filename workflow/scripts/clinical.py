"""Snakemake adapter: the paper's Table 3 for the clinical cases, and their error fields as XDMF."""

from pathlib import Path

from surrogate.runtime import configure_cpu

configure_cpu()

from fem.case_files import read_summary  # noqa: E402
from fem.dataset import read_dataset  # noqa: E402
from fem.sweep import clinical_list  # noqa: E402
from run.joblog import job_log  # noqa: E402
from studies.surrogate_study.surrogate_evaluation import ClinicalEvaluation, evaluate_clinical  # noqa: E402
from surrogate.predict import Surrogate  # noqa: E402

job_log(snakemake.log[0])

dataset = read_dataset(snakemake.input.dataset)
models = {
    "by_sample": Surrogate.load(snakemake.input.model),
    "by_case": Surrogate.load(snakemake.input.model_by_case),
}
fe_wall = {}
for path in snakemake.input.summaries:
    summary = read_summary(path)
    fe_wall[summary["case"]] = summary["wall_s"]["solve"]
fields = {
    (Path(p).parent.name, Path(p).stem): p for p in snakemake.output.fields if p.endswith(".xdmf")
}
result = evaluate_clinical(
    models, dataset, clinical_list(snakemake.params.clinical), fe_wall, snakemake.input.mesh,
    fields,
)
ClinicalEvaluation.from_json(result).write(snakemake.output.table)

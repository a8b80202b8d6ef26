"""Snakemake adapter: one training run (a study repeat, an ablation or the by-case model)."""

from pathlib import Path

from surrogate.runtime import configure_cpu

configure_cpu(single_thread=snakemake.threads == 1)  # before JAX starts: one core per job

from fem.dataset import read_dataset  # noqa: E402
from fem.sweep import clinical_cases  # noqa: E402
from run.joblog import job_log  # noqa: E402
from studies.fe_study.stability_audit import without_unstable  # noqa: E402
from studies.surrogate_study.architecture import ArchitectureTable  # noqa: E402
from surrogate.checkpoint import save_model  # noqa: E402
from surrogate.config import SurrogateConfig  # noqa: E402
from surrogate.structures import structure_for  # noqa: E402
from surrogate.train import train_and_evaluate  # noqa: E402

job_log(snakemake.log[0])

wildcards = snakemake.wildcards
if hasattr(wildcards, "arch"):
    architecture = wildcards.arch
else:  # ablations and the by-case model use the architecture the study selected
    architecture = ArchitectureTable.read(snakemake.input.table).selected_architecture
config = SurrogateConfig.from_mapping(dict(snakemake.params.surrogate)).with_architecture(
    architecture
)
# repeat r trains with seed + r: the same seeds in the study and in every ablation
config = config.replace(seed=config.seed + int(getattr(wildcards, "repeat", 0)))

# a pod model takes its modes at every node of a quadratic mesh, where the dataset has them
dataset = read_dataset(snakemake.input.dataset, nodes=structure_for(config).reads_nodes)
dataset = without_unstable(dataset, snakemake.input.audit)  # no sample of an unstable state
holdout = [
    dataset.case_index(c.C1, c.phi, c.theta) for c in clinical_cases(snakemake.params.holdout)
]
result = train_and_evaluate(dataset, config, progress=False, holdout=holdout or None)
save_model(Path(snakemake.output.model).parent, result, dataset)

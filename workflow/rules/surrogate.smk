# Surrogate: the architecture study (the paper's Table 2), the selected model, variants of the
# settings (e.g. the exact Dirichlet condition), the by-case model, the clinical cases (Tables 3
# and 4), extrapolation outside the sweep, and the benchmark of the goals.
from snakemake.exceptions import WorkflowError

from surrogate.config import SurrogateConfig, SurrogateConfigError, parse_architecture

STUDY = config["surrogate_study"]
SURROGATE_DIR = "results/surrogate"
STUDY_DIR = f"{SURROGATE_DIR}/study"
STUDY_TABLE = f"{STUDY_DIR}/table2.json"
VARIANT_DIR = f"{SURROGATE_DIR}/variants"
MODEL_BY_CASE = f"{SURROGATE_DIR}/model_by_case/model.json"
CLINICAL_JSON = f"{SURROGATE_DIR}/clinical.json"
EXTRAPOLATION_JSON = f"{SURROGATE_DIR}/extrapolation.json"
VARIANTS_JSON = f"{SURROGATE_DIR}/variants.json"
BENCHMARK_JSON = f"{SURROGATE_DIR}/benchmark.json"
MODEL_FILES = ("model.json", "params.npz", "history.json")


def surrogate_settings(overrides=None):
    """The `surrogate` section with a variant's overrides, checked (raises before any job)."""
    try:
        return SurrogateConfig.from_mapping({**config["surrogate"], **(overrides or {})})
    except SurrogateConfigError as err:
        raise WorkflowError(f"invalid configuration: {err}") from None


def check_surrogate_config():
    surrogate_settings()
    for name, overrides in STUDY["variants"].items():
        surrogate_settings(overrides)
    try:
        archs = [parse_architecture(a) for a in STUDY["architectures"]]
    except SurrogateConfigError as err:
        raise WorkflowError(f"invalid configuration: surrogate_study.architectures: {err}") from None
    if len(set(archs)) != len(archs):
        raise WorkflowError("invalid configuration: surrogate_study.architectures lists one twice")


check_surrogate_config()
ARCHITECTURES = ["{}x{}".format(*parse_architecture(a)) for a in STUDY["architectures"]]
REPEATS = list(range(STUDY["repeats"]))


def extrapolation_cases():
    """The extra FE cases of `surrogate_study.extrapolation` that are not in the sweep."""
    extra = set()
    for block in STUDY["extrapolation"]:
        extra.update(sweep_cases(block))
    return sorted(extra - set(CASES))


EXTRA_CASES = extrapolation_cases()


def clinical_ids():
    """Case folder names of the clinical cases (FE_CLINICAL_CASES: fe_study.smk)."""
    return [case.id for case in FE_CLINICAL_CASES]


def study_runs(name="model.json"):
    return expand(f"{STUDY_DIR}/{{arch}}/r{{repeat}}/{name}", arch=ARCHITECTURES, repeat=REPEATS)


def variant_runs(name="model.json"):
    return expand(f"{VARIANT_DIR}/{{variant}}/r{{repeat}}/{name}", variant=list(STUDY["variants"]),
                  repeat=REPEATS)


def variant_params(wildcards):
    """Settings of one variant (its architecture comes from the study's selection)."""
    return surrogate_settings(STUDY["variants"][wildcards.variant]).as_dict()


def clinical_fields():
    return expand(f"{SURROGATE_DIR}/clinical/{{split}}/{{case}}.{{ext}}",
                  split=["by_sample", "by_case"], case=clinical_ids(), ext=["xdmf", "h5"])


SURROGATE_RESULTS = [STUDY_TABLE, VARIANTS_JSON, CLINICAL_JSON, EXTRAPOLATION_JSON, BENCHMARK_JSON]


wildcard_constraints:
    arch=r"[0-9]+x[0-9]+",
    repeat=r"[0-9]+",
    variant=r"[A-Za-z][A-Za-z0-9_]*",


# One job per (architecture, repeat): one core each, so `-j2` runs two at once.
rule study_run:
    input:
        dataset=DATASET,
    output:
        model=f"{STUDY_DIR}/{{arch}}/r{{repeat}}/model.json",
        params=f"{STUDY_DIR}/{{arch}}/r{{repeat}}/params.npz",
        history=f"{STUDY_DIR}/{{arch}}/r{{repeat}}/history.json",
    params:
        surrogate=surrogate_settings().as_dict(),
        holdout=[],
    log:
        "results/logs/surrogate/study/{arch}_r{repeat}.log",
    benchmark:
        "results/benchmarks/surrogate/study/{arch}_r{repeat}.tsv"
    threads: 1
    resources:
        mem_mb=4000,
    script:
        "../scripts/train_run.py"


# Table 2 and the selection (within surrogate_study.prediction_budget_ms); times each
# architecture's best model on one pinned core (two threads reserved so that no other job of
# the workflow runs beside the timing).
rule architecture_study:
    input:
        runs=study_runs(),
    output:
        table=STUDY_TABLE,
    params:
        clinical=config["clinical"],
        repeats=STUDY["timing_repeats"],
        budget_ms=STUDY["prediction_budget_ms"],
    log:
        "results/logs/surrogate/architecture_study.log",
    threads: 2
    resources:
        mem_mb=2000,
    script:
        "../scripts/study_table.py"


# The model used downstream: the selected architecture's best run, copied (not retrained).
rule train:
    input:
        table=STUDY_TABLE,
    output:
        model=MODEL,
        params=f"{SURROGATE_DIR}/model/params.npz",
        history=f"{SURROGATE_DIR}/model/history.json",
    log:
        "results/logs/train.log",
    threads: 1
    resources:
        mem_mb=500,
    script:
        "../scripts/select_model.py"


rule variant_run:
    input:
        dataset=DATASET,
        table=STUDY_TABLE,
    output:
        model=f"{VARIANT_DIR}/{{variant}}/r{{repeat}}/model.json",
        params=f"{VARIANT_DIR}/{{variant}}/r{{repeat}}/params.npz",
        history=f"{VARIANT_DIR}/{{variant}}/r{{repeat}}/history.json",
    params:
        surrogate=variant_params,
        holdout=[],
    log:
        "results/logs/surrogate/variants/{variant}_r{repeat}.log",
    benchmark:
        "results/benchmarks/surrogate/variants/{variant}_r{repeat}.tsv"
    threads: 1
    resources:
        mem_mb=4000,
    script:
        "../scripts/train_run.py"


rule variants:
    input:
        table=STUDY_TABLE,
        study_runs=study_runs(),
        variant_runs=variant_runs(),
    output:
        VARIANTS_JSON,
    log:
        "results/logs/surrogate/variants.log",
    threads: 1
    resources:
        mem_mb=500,
    script:
        "../scripts/variants.py"


# The by-case model: the selected architecture trained on whole cases, the clinical cases
# kept out of training and validation.
rule train_by_case:
    input:
        dataset=DATASET,
        table=STUDY_TABLE,
    output:
        model=MODEL_BY_CASE,
        params=f"{SURROGATE_DIR}/model_by_case/params.npz",
        history=f"{SURROGATE_DIR}/model_by_case/history.json",
    params:
        surrogate=surrogate_settings({"split": "by_case"}).as_dict(),
        holdout=config["clinical"],
    log:
        "results/logs/surrogate/train_by_case.log",
    benchmark:
        "results/benchmarks/surrogate/train_by_case.tsv"
    threads: 1
    resources:
        mem_mb=4000,
    script:
        "../scripts/train_run.py"


rule clinical:
    input:
        dataset=DATASET,
        model=MODEL,
        model_by_case=MODEL_BY_CASE,
        mesh=MESH,
        summaries=expand(f"results/cases/{{case}}/summary.json", case=clinical_ids()),
    output:
        table=CLINICAL_JSON,
        fields=clinical_fields(),
    params:
        clinical=config["clinical"],
    log:
        "results/logs/surrogate/clinical.log",
    threads: 1
    resources:
        mem_mb=2000,
    script:
        "../scripts/clinical.py"


# FE cases outside the sweep (C1 below/above its range, unseen Phi, theta off the plane),
# solved by `solve_outside` into results/outside/, never added to the dataset.
rule extrapolation:
    input:
        dataset=DATASET,
        model=MODEL,
        model_by_case=MODEL_BY_CASE,
        summaries=[f"results/outside/{case.id}/summary.json" for case in EXTRA_CASES],
        points=[f"results/outside/{case.id}/points.h5" for case in EXTRA_CASES],
    output:
        EXTRAPOLATION_JSON,
    log:
        "results/logs/surrogate/extrapolation.log",
    threads: 1
    resources:
        mem_mb=2000,
    script:
        "../scripts/extrapolation.py"


# Both threads reserved: the job pins itself to one core and times the FE solver and the
# surrogate there, with no other job of the workflow beside it.
rule surrogate_benchmark:
    input:
        model=MODEL,
        mesh=MESH,
        table=STUDY_TABLE,
        clinical=CLINICAL_JSON,
        variants=VARIANTS_JSON,
    output:
        BENCHMARK_JSON,
    params:
        clinical=config["clinical"],
        repeats=STUDY["timing_repeats"],
        fe=config["fe"],
        material=config["material"],
        fixed=config["mesh"]["fixed"],
    log:
        "results/logs/surrogate/benchmark.log",
    threads: 2
    resources:
        mem_mb=4000,
    script:
        "../scripts/benchmark.py"

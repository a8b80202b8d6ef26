# Surrogate: the architecture study (the paper's Table 2), the selected model, variants of the
# settings (e.g. the exact Dirichlet condition), the by-case model, the clinical cases (Tables 3
# and 4), extrapolation outside the sweep, and the benchmark of the goals.
wildcard_constraints:
    arch=r"[0-9]+x[0-9]+",
    repeat=r"[0-9]+",
    variant=r"[A-Za-z][A-Za-z0-9_]*",


# One training per (architecture, repeat): one core each, so `-j2` runs two at once.
rule train_study_run:
    input:
        dataset=DATASET,
    output:
        model=f"{STUDY_DIR}/{{arch}}/r{{repeat}}/model.json",
        params=f"{STUDY_DIR}/{{arch}}/r{{repeat}}/params.npz",
        history=f"{STUDY_DIR}/{{arch}}/r{{repeat}}/history.json",
    params:
        surrogate=CONFIG.surrogate.as_dict(),
        holdout=[],
    log:
        "results/logs/surrogate/study/{arch}_r{repeat}.log",
    benchmark:
        "results/benchmarks/surrogate/study/{arch}_r{repeat}.tsv"
    threads: 1
    resources:
        mem_mb=4000,
    conda:
        ENV
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
        clinical=CONFIG.section("clinical"),
        repeats=CONFIG.surrogate_study.timing_repeats,
        budget_ms=CONFIG.surrogate_study.prediction_budget_ms,
    log:
        "results/logs/surrogate/architecture_study.log",
    threads: 2
    resources:
        mem_mb=2000,
    conda:
        ENV
    script:
        "../scripts/study_table.py"


# The model used downstream: the selected architecture's best run, copied (not retrained).
rule select_model:
    input:
        table=STUDY_TABLE,
        dataset=DATASET,
    output:
        model=MODEL,
        params=f"{SURROGATE_DIR}/model/params.npz",
        history=f"{SURROGATE_DIR}/model/history.json",
    log:
        "results/logs/surrogate/select_model.log",
    threads: 1
    resources:
        mem_mb=500,
    conda:
        ENV
    script:
        "../scripts/select_model.py"


# One training per (variant, repeat), at the selected architecture.
rule train_variant_run:
    input:
        dataset=DATASET,
        table=STUDY_TABLE,
    output:
        model=f"{VARIANT_DIR}/{{variant}}/r{{repeat}}/model.json",
        params=f"{VARIANT_DIR}/{{variant}}/r{{repeat}}/params.npz",
        history=f"{VARIANT_DIR}/{{variant}}/r{{repeat}}/history.json",
    params:
        surrogate=variant_settings,
        holdout=[],
    log:
        "results/logs/surrogate/variants/{variant}_r{repeat}.log",
    benchmark:
        "results/benchmarks/surrogate/variants/{variant}_r{repeat}.tsv"
    threads: 1
    resources:
        mem_mb=4000,
    conda:
        ENV
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
    conda:
        ENV
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
        surrogate=CONFIG.surrogate_by_case.as_dict(),
        holdout=CONFIG.section("clinical"),
    log:
        "results/logs/surrogate/train_by_case.log",
    benchmark:
        "results/benchmarks/surrogate/train_by_case.tsv"
    threads: 1
    resources:
        mem_mb=4000,
    conda:
        ENV
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
        clinical=CONFIG.section("clinical"),
    log:
        "results/logs/surrogate/clinical.log",
    threads: 1
    resources:
        mem_mb=2000,
    conda:
        ENV
    script:
        "../scripts/clinical.py"


# FE cases outside the sweep (C1 below/above its range, unseen Phi, theta off the plane),
# solved by `solve_outside` into results/outside/, never added to the dataset.
rule extrapolation:
    input:
        dataset=DATASET,
        model=MODEL,
        model_by_case=MODEL_BY_CASE,
        summaries=extrapolation_files("summary.json"),
        points=extrapolation_files("points.h5"),
    output:
        EXTRAPOLATION_JSON,
    log:
        "results/logs/surrogate/extrapolation.log",
    threads: 1
    resources:
        mem_mb=2000,
    conda:
        ENV
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
        clinical=CONFIG.section("clinical"),
        repeats=CONFIG.surrogate_study.timing_repeats,
        fe=CONFIG.solve_fe,
        material=CONFIG.section("material"),
        fixed=CONFIG.section("mesh", "fixed"),
    log:
        "results/logs/surrogate/benchmark.log",
    threads: 2
    resources:
        mem_mb=4000,
    conda:
        ENV
    script:
        "../scripts/benchmark.py"

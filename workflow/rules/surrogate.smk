# Surrogate: the architecture study (the paper's Table 2), the selected model, ablations of
# the settings (e.g. the paper's own protocol), the held-out models, the clinical cases (Tables
# 3 and 4), extrapolation outside the sweep, and the benchmark of the goals.
wildcard_constraints:
    arch=r"[0-9]+x[0-9]+",
    held_out="by_case|by_direction|by_c1",
    repeat=r"[0-9]+",
    ablation=r"[A-Za-z][A-Za-z0-9_]*",


# One training per (architecture, repeat): one core each, so `-j2` runs two at once.
rule train_study_run:
    input:
        dataset=DATASET,
        audit=FE_STABILITY_AUDIT_JSON,
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
    priority: 40
    threads: 1
    resources:
        mem_mb=4000,
    conda:
        ENV
    script:
        "../scripts/train_run.py"


# With surrogate_study.repeat_within: which architectures train their repeats, those whose first
# run is close to the best first run (the study's other runs wait for this plan).
checkpoint study_repeats:
    input:
        runs=first_study_runs(),
    output:
        STUDY_REPEATS,
    params:
        repeats=CONFIG.surrogate_study.repeats,
        within=CONFIG.surrogate_study.repeat_within,
    log:
        "results/logs/surrogate/study_repeats.log",
    priority: 40
    threads: 1
    resources:
        mem_mb=500,
    conda:
        ENV
    script:
        "../scripts/study_repeats.py"


# Table 2 and the selection (within surrogate_study.prediction_budget_ms); times each
# architecture's best model on one pinned core (two threads reserved so that no other job of
# the workflow runs beside the timing).
rule architecture_study:
    input:
        runs=study_runs(),
        runs_arrays=study_runs("params.npz"),
    output:
        table=STUDY_TABLE,
    params:
        clinical=CONFIG.section("clinical"),
        repeats=CONFIG.surrogate_study.timing_repeats,
        budget_ms=CONFIG.surrogate_study.prediction_budget_ms,
        study_repeats=CONFIG.surrogate_study.repeats,
        within=CONFIG.surrogate_study.repeat_within,
    log:
        "results/logs/surrogate/architecture_study.log",
    priority: 40
    threads: 2
    resources:
        mem_mb=2000,
    conda:
        ENV
    script:
        "../scripts/architecture_study.py"


# The model used downstream: the selected architecture's best run, trained again on its
# validation data too for the epochs that run chose (surrogate_study.refit), or copied.
rule select_model:
    input:
        table=STUDY_TABLE,
        dataset=DATASET,
        audit=FE_STABILITY_AUDIT_JSON,
    output:
        model=MODEL,
        params=MODEL_ARRAYS,
        history=f"{SURROGATE_DIR}/model/history.json",
    params:
        refit=CONFIG.surrogate_study.refit,
    log:
        "results/logs/surrogate/select_model.log",
    benchmark:
        "results/benchmarks/surrogate/select_model.tsv"
    priority: 40
    threads: 1
    resources:
        mem_mb=lambda wildcards: 4000 if CONFIG.surrogate_study.refit else 500,
    conda:
        ENV
    script:
        "../scripts/select_model.py"


# One training per (ablation, repeat), at the selected architecture.
rule train_ablation_run:
    input:
        dataset=DATASET,
        audit=FE_STABILITY_AUDIT_JSON,
        table=STUDY_TABLE,
    output:
        model=f"{ABLATION_DIR}/{{ablation}}/r{{repeat}}/model.json",
        params=f"{ABLATION_DIR}/{{ablation}}/r{{repeat}}/params.npz",
        history=f"{ABLATION_DIR}/{{ablation}}/r{{repeat}}/history.json",
    params:
        surrogate=ablation_settings,
        holdout=[],
    log:
        "results/logs/surrogate/ablations/{ablation}_r{repeat}.log",
    benchmark:
        "results/benchmarks/surrogate/ablations/{ablation}_r{repeat}.tsv"
    threads: 1
    resources:
        mem_mb=4000,
    conda:
        ENV
    script:
        "../scripts/train_run.py"


rule ablations:
    input:
        table=STUDY_TABLE,
        study_runs=study_runs(),
        ablation_runs=ablation_runs(),
    output:
        ABLATIONS_JSON,
    log:
        "results/logs/surrogate/ablations.log",
    threads: 1
    resources:
        mem_mb=500,
    conda:
        ENV
    script:
        "../scripts/ablations.py"


# The held-out models: the selected architecture trained on the dataset's splits that hold out
# whole groups: by_case (the clinical cases kept out of training and validation as well),
# by_direction (whole gravity directions) and by_c1 (whole C1 values), each judged on its
# held-out test cases by `held_out`.
rule train_held_out:
    input:
        dataset=DATASET,
        audit=FE_STABILITY_AUDIT_JSON,
        table=STUDY_TABLE,
    output:
        model=f"{SURROGATE_DIR}/model_{{held_out}}/model.json",
        params=f"{SURROGATE_DIR}/model_{{held_out}}/params.npz",
        history=f"{SURROGATE_DIR}/model_{{held_out}}/history.json",
    params:
        surrogate=lambda wildcards: CONFIG.surrogate_held_out(wildcards.held_out).as_dict(),
        holdout=lambda wildcards: CONFIG.section("clinical") if wildcards.held_out == "by_case" else [],
    log:
        "results/logs/surrogate/train_{held_out}.log",
    benchmark:
        "results/benchmarks/surrogate/train_{held_out}.tsv"
    threads: 1
    resources:
        mem_mb=4000,
    conda:
        ENV
    script:
        "../scripts/train_run.py"


# Each held-out model's errors on its test cases (mean, 95th percentile and max per case, mm
# and relative), beside the by-sample model's on the same cases: at the material points and,
# where the dataset has a quadratic mesh's nodes, at its cell centroids between them.
rule held_out:
    input:
        dataset=DATASET,
        audit=FE_STABILITY_AUDIT_JSON,
        model=MODEL,
        model_arrays=MODEL_ARRAYS,
        held_out=held_out_models(),
        held_out_arrays=held_out_models("params.npz"),
    output:
        HELD_OUT_JSON,
    params:
        splits=CONFIG.held_out_splits,
    log:
        "results/logs/surrogate/held_out.log",
    threads: 1
    resources:
        mem_mb=2000,
    conda:
        ENV
    script:
        "../scripts/held_out.py"


rule clinical:
    input:
        dataset=DATASET,
        model=MODEL,
        model_arrays=MODEL_ARRAYS,
        model_by_case=MODEL_BY_CASE,
        model_by_case_arrays=MODEL_BY_CASE_ARRAYS,
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
        model_arrays=MODEL_ARRAYS,
        model_by_case=MODEL_BY_CASE,
        model_by_case_arrays=MODEL_BY_CASE_ARRAYS,
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


# The model in the postures a patient takes (surrogate_study.postures), against FE: the sweep's
# cases where it has them, else extra solves by `solve_outside`; at the material points and at
# the quadratic mesh's cell centroids (from each case's fields.h5), between them.
rule postures:
    input:
        model=MODEL,
        model_arrays=MODEL_ARRAYS,
        summaries=posture_files("summary.json"),
        points=posture_files("points.h5"),
        fields=posture_files("fields.h5"),
    output:
        POSTURES_JSON,
    params:
        postures=[(p.name, p.in_sweep) for p in CONFIG.surrogate_study.postures],
    log:
        "results/logs/surrogate/postures.log",
    threads: 1
    resources:
        mem_mb=2000,
    conda:
        ENV
    script:
        "../scripts/postures.py"


# The model at random cases off the sweep's grid (surrogate_study.off_grid), each an extra FE
# solve by `solve_outside`: what a user meets between the sweep's points.
rule off_grid:
    input:
        model=MODEL,
        model_arrays=MODEL_ARRAYS,
        summaries=off_grid_files("summary.json"),
        points=off_grid_files("points.h5"),
        fields=off_grid_files("fields.h5"),
    output:
        OFF_GRID_JSON,
    log:
        "results/logs/surrogate/off_grid.log",
    threads: 1
    resources:
        mem_mb=2000,
    conda:
        ENV
    script:
        "../scripts/off_grid.py"


# Where the selected model warns that no FE solution backs a query, over the range it was
# trained on (studies.surrogate_study.warning_coverage): queries drawn evenly, their checks run without the
# network, the share warned by C1 band and by kind.
rule warning_coverage:
    input:
        model=MODEL,
        model_arrays=MODEL_ARRAYS,
    output:
        WARNING_COVERAGE_JSON,
    log:
        "results/logs/surrogate/warning_coverage.log",
    threads: 1
    resources:
        mem_mb=1000,
    conda:
        ENV
    script:
        "../scripts/warning_coverage.py"


# Both threads reserved: the job pins itself to one core and times the FE solver and the
# surrogate there, with no other job of the workflow beside it.
rule surrogate_benchmark:
    input:
        model=MODEL,
        model_arrays=MODEL_ARRAYS,
        mesh=MESH,
        table=STUDY_TABLE,
        clinical=CLINICAL_JSON,
        ablations=ABLATIONS_JSON,
    output:
        SURROGATE_BENCHMARK_JSON,
    params:
        clinical=CONFIG.section("clinical"),
        repeats=CONFIG.surrogate_study.timing_repeats,
        **CONFIG.solver_params,
    log:
        "results/logs/surrogate/surrogate_benchmark.log",
    threads: 2
    resources:
        mem_mb=4000,
    conda:
        ENV
    script:
        "../scripts/surrogate_benchmark.py"

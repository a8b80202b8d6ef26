# What the first report reads (rule first_report), which the full report reads too: its sections
# from these inputs are the same on both pages.
FIRST_REPORT_INPUTS = dict(
    dataset=DATASET,
    quality="results/mesh/quality.json",
    rest_pairs="results/mesh/self_contact_at_rest.json",
    mesh_png="results/mesh/mesh.png",
    model=MODEL,
    history=f"{SURROGATE_DIR}/model/history.json",
    table2=STUDY_TABLE,
    viewer=VIEWER,
    # the adaptive sweep's rounds, gathered (sweep.smk); a fixed design has none
    sweep_rounds=[SWEEP_ROUNDS_JSON] if ADAPTIVE is not None else [],
)


# The report: one HTML page with its PNG figures beside it (report.build). It reads every
# result of the workflow, so `rule all`, which asks for it, pulls in the FE sweep, the FE study
# and the surrogate's study, models and benchmarks.


rule report:
    input:
        **FIRST_REPORT_INPUTS,
        ablations=ABLATIONS_JSON,
        clinical=CLINICAL_JSON,
        extrapolation=EXTRAPOLATION_JSON,
        held_out=HELD_OUT_JSON,
        postures=POSTURES_JSON,
        off_grid=OFF_GRID_JSON,
        warning_coverage=WARNING_COVERAGE_JSON,
        surrogate_benchmark=SURROGATE_BENCHMARK_JSON,
        clinical_fields=clinical_fields(),
        fe_clinical=FE_CLINICAL_JSON,
        fe_speed_accuracy=FE_SPEED_ACCURACY_JSON,
        fe_convergence_map=FE_CONVERGENCE_MAP_JSON,
        fe_failure_edges=FE_FAILURE_EDGES_JSON,
        fe_stability_audit=FE_STABILITY_AUDIT_JSON,
        fe_fold_section=FE_FOLD_SECTION_JSON,
        fe_skin=FE_SKIN_JSON,
        corpus=CORPUS_JSON,
        reference_roundtrip=REFERENCE_ROUNDTRIP_JSON,
        # the imaged chain's results where reference_state.imaged is set (else empty)
        reference_record=[REFERENCE_RECORD] if IMAGED else [],
        tracking=TRACKING_JSON,
        stiffness=[STIFFNESS_JSON] if IMAGED and IMAGED.observation else [],
        # whether the sweep's error estimate ranks the surrogate's true error (sweep.smk)
        sweep_estimate=SWEEP_ESTIMATE_JSON,
    output:
        html=REPORT,
    params:
        clinical=CONFIG.section("clinical"),
        first=False,
    log:
        "results/logs/report.log",
    threads: 1
    resources:
        mem_mb=4000,
    conda:
        ENV
    script:
        "../scripts/report.py"


# The first report: the same page from the results a user looks at first (the mesh, the dataset,
# the selected model, its training and Table 2, the 3D view), written as soon as they exist,
# before the long studies (the FE study among them); the full report follows them.
rule first_report:
    input:
        **FIRST_REPORT_INPUTS,
    output:
        html=FIRST_REPORT,
    params:
        clinical=CONFIG.section("clinical"),
        first=True,
    log:
        "results/logs/first_report.log",
    priority: 40
    threads: 1
    resources:
        mem_mb=4000,
    conda:
        ENV
    script:
        "../scripts/report.py"


# The interactive 3D view (report.viewer): one page that opens from the file system, with the
# selected surrogate predicting in the browser and the FE solutions of some sweep cases.
rule viewer:
    input:
        model=MODEL,
        model_arrays=MODEL_ARRAYS,
        mesh=MESH,
        dataset=DATASET,
        # with reference_state.points: each set's material positions, found by rule tracking
        tracked=TRACKING_JSON,
    output:
        html=VIEWER,
        licence="results/viewer/THREE-LICENSE.txt",
    params:
        clinical=CONFIG.section("clinical"),
        postures=CONFIG.section("surrogate_study", "postures", "directions"),
        # with an imaged breast, movement is first measured from the posture it was imaged in
        start=None if IMAGED is None else IMAGED.posture(),
        initial=None if IMAGED is None else IMAGED.view_query(),
    log:
        "results/logs/viewer.log",
    priority: 40
    threads: 1
    resources:
        mem_mb=2000,
    conda:
        ENV
    script:
        "../scripts/viewer.py"

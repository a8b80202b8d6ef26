# FE study: the clinical benchmark (time, factorisation equivalents, a fixed-step baseline,
# accuracy against a refined reference), speed against accuracy over mesh sizes x elements x
# solver presets, and convergence maps over (C1, Phi) for adaptive and fixed-step loading.
# Benchmarks, not tests: `snakemake -j2 fe_study` runs them alone; the report needs them. The
# library code is in studies/ (fe_clinical, fe_speed_accuracy,
# convergence_map); JSON results land in results/fe_study/.
wildcard_constraints:
    fe_mesh=MESH_ID_PATTERN,
    fe_variant=FE_VARIANT_ID_PATTERN,
    part=r"[0-9]+",


rule fe_study:
    input:
        FE_STUDY_RESULTS,


rule fe_study_mesh:
    output:
        xdmf=f"{FE_STUDY_DIR}/meshes/{{fe_mesh}}/mesh.xdmf",
        h5=f"{FE_STUDY_DIR}/meshes/{{fe_mesh}}/mesh.h5",
        quality=f"{FE_STUDY_DIR}/meshes/{{fe_mesh}}/quality.json",
        png=f"{FE_STUDY_DIR}/meshes/{{fe_mesh}}/mesh.png",
    params:
        mesh=CONFIG.section("mesh"),
    log:
        f"results/logs/fe_study/mesh_{{fe_mesh}}.log",
    threads: 1
    resources:
        mem_mb=4000,
    conda:
        ENV
    script:
        "../scripts/fe_study_mesh.py"


rule fe_reference:
    input:
        mesh=fe_study_mesh(CONFIG.fe_study.reference.mesh),
    output:
        f"{FE_STUDY_DIR}/reference/{CASE_WILDCARDS}.h5",
    params:
        config=CONFIG.fe_study.base_config,
        reference=CONFIG.section("fe_study", "reference"),
    log:
        f"results/logs/fe_study/reference_{CASE_WILDCARDS}.log",
    benchmark:
        f"results/benchmarks/fe_study/reference_{CASE_WILDCARDS}.tsv"
    # One reference at a time, on every core (multi-threaded BLAS): the default reference's
    # solve peaks at 12-13 GB.
    threads: all_cores()
    resources:
        mem_mb=16000,
    conda:
        ENV
    script:
        "../scripts/fe_reference.py"


rule fe_clinical:
    input:
        mesh=MESH,
        reference_mesh=fe_study_mesh(CONFIG.fe_study.reference.mesh),
        references=fe_references,
    output:
        FE_CLINICAL_JSON,
    params:
        config=CONFIG.sections_of("fe", "material", "mesh"),
        clinical=CONFIG.section("clinical"),
        study=CONFIG.section("fe_study", "clinical"),
    log:
        "results/logs/fe_study/clinical.log",
    # All of Snakemake's cores, so that no other job of this run shares the machine
    # while the timings are taken; the solve itself is single-threaded (one core).
    threads: all_cores()
    resources:
        mem_mb=4000,
    conda:
        ENV
    script:
        "../scripts/fe_clinical.py"


rule fe_variant:
    input:
        mesh=fe_variant_mesh,
        reference_mesh=fe_study_mesh(CONFIG.fe_study.reference.mesh),
        references=fe_references,
    output:
        f"{FE_STUDY_DIR}/speed_accuracy/{{fe_variant}}.json",
    params:
        config=CONFIG.fe_study.base_config,
        clinical=CONFIG.section("clinical"),
        max_dofs=CONFIG.fe_study.max_dofs,
    log:
        f"results/logs/fe_study/variant_{{fe_variant}}.log",
    threads: all_cores()  # timed: run alone (see fe_clinical)
    resources:
        mem_mb=8000,
    conda:
        ENV
    script:
        "../scripts/fe_variant.py"


rule fe_speed_accuracy:
    input:
        expand(f"{FE_STUDY_DIR}/speed_accuracy/{{fe_variant}}.json",
               fe_variant=[v.id for v in CONFIG.fe_study.variants]),
    output:
        FE_SPEED_ACCURACY_JSON,
    params:
        target=CONFIG.fe_study.target,
        default_variant=CONFIG.fe_study.default_variant.id,
    log:
        "results/logs/fe_study/speed_accuracy.log",
    threads: 1
    conda:
        ENV
    script:
        "../scripts/fe_speed_accuracy.py"


rule fe_convergence_map:
    input:
        mesh=fe_study_mesh(CONFIG.fe_study.convergence_map_mesh),
    output:
        FE_CONVERGENCE_MAP_JSON,
    params:
        config=CONFIG.sections_of("fe", "material", "mesh"),
        convergence_map=CONFIG.section("fe_study", "convergence_map"),
    log:
        "results/logs/fe_study/convergence_map.log",
    threads: 1
    resources:
        mem_mb=4000,
    conda:
        ENV
    script:
        "../scripts/fe_convergence_map.py"


# The sweep's failed cases traced from their nearest converged direction (studies.fe_study.failure_edge):
# where the solution ends, and whether every state before it is stable. It reads the sweep's
# dataset, so it is not part of `snakemake fe_study`; the report asks for it.
rule fe_failure_edges:
    input:
        mesh=MESH,
        dataset=DATASET,
    output:
        FE_FAILURE_EDGES_JSON,
    params:
        config=CONFIG.sections_of("fe", "material", "mesh"),
        n=CONFIG.fe_study.failure_edges.n,
        step_deg=CONFIG.fe_study.failure_edges.step_deg,
        resolution_deg=CONFIG.fe_study.failure_edges.resolution_deg,
    log:
        "results/logs/fe_study/failure_edges.log",
    threads: 1
    resources:
        mem_mb=4000,
    conda:
        ENV
    script:
        "../scripts/fe_failure_edges.py"


# Every training waits for the audit, so its cases are shared by fe_study.stability_audit.jobs
# one-core jobs side by side (each every jobs-th case), joined into one record.
rule fe_stability_audit_part:
    input:
        mesh=MESH,
        dataset=DATASET,
    output:
        temp(f"{FE_STUDY_DIR}/stability_audit/part{{part}}.json"),
    params:
        config=CONFIG.sections_of("fe", "material", "mesh"),
        softest=CONFIG.fe_study.stability_audit.softest,
        parts=CONFIG.fe_study.stability_audit.jobs,
    log:
        "results/logs/fe_study/stability_audit_part{part}.log",
    benchmark:
        "results/benchmarks/fe_study/stability_audit_part{part}.tsv"
    priority: 50
    threads: 1
    resources:
        mem_mb=4000,
    conda:
        ENV
    script:
        "../scripts/fe_stability_audit.py"


rule fe_stability_audit:
    input:
        expand(f"{FE_STUDY_DIR}/stability_audit/part{{part}}.json",
               part=range(CONFIG.fe_study.stability_audit.jobs)),
    output:
        FE_STABILITY_AUDIT_JSON,
    log:
        "results/logs/fe_study/stability_audit.log",
    priority: 50
    threads: 1
    resources:
        mem_mb=500,
    conda:
        ENV
    script:
        "../scripts/fe_stability_audit_merge.py"


# The fold with and without the skin's self-contact (studies.fe_study.fold_section): the named cases and
# the sweep's largest self-contact forces, each solved both ways and cut at the fold, for the
# report's picture. It reads the sweep's dataset, so it is not part of `snakemake fe_study`.
rule fe_fold_section:
    input:
        mesh=MESH,
        dataset=DATASET,
    output:
        FE_FOLD_SECTION_JSON,
    params:
        config=CONFIG.sections_of("fe", "material", "mesh"),
        cases=CONFIG.fe_study.fold_section.cases,
        largest=CONFIG.fe_study.fold_section.largest,
    log:
        "results/logs/fe_study/fold_section.log",
    benchmark:
        "results/benchmarks/fe_study/fold_section.tsv"
    threads: 1
    resources:
        mem_mb=4000,
    conda:
        ENV
    script:
        "../scripts/fe_fold_section.py"


# What the skin changes (studies.fe_study.skin): the clinical cases on the workflow's mesh homogeneous and
# with the skin membrane at each of fe_study.skin's ratios and thicknesses, and a tumour point's
# prone-to-supine path with each. Like the fold's cut it feeds the full report only, not the
# first report, and is not part of `snakemake fe_study`.
rule fe_skin:
    input:
        mesh=MESH,
    output:
        FE_SKIN_JSON,
    params:
        config=CONFIG.sections_of("fe", "material", "mesh"),
        clinical=CONFIG.section("clinical"),
        ratios=CONFIG.fe_study.skin.ratios,
        thicknesses=CONFIG.fe_study.skin.thicknesses,
        tumour=CONFIG.fe_study.skin.tumour,
    log:
        "results/logs/fe_study/skin.log",
    benchmark:
        "results/benchmarks/fe_study/skin.tsv"
    threads: 1
    resources:
        mem_mb=4000,
    conda:
        ENV
    script:
        "../scripts/fe_skin.py"

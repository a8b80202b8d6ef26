# FE study (issue 4): the clinical benchmark (time, factorisation equivalents, a fixed-step
# baseline, accuracy against a refined reference), speed against accuracy over mesh sizes x
# elements x solver presets, and stability maps over (C1, Phi) for adaptive and fixed-step
# loading. Benchmarks, not tests: `snakemake -j2 fe_study` runs them alone; the report needs
# them. The library code is in studies/ (fe_benchmark, fe_speed_accuracy, stability); JSON results land in
# results/fe_study/.
wildcard_constraints:
    fe_mesh=MESH_ID_PATTERN,
    fe_variant=VARIANT_ID_PATTERN,


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
        mesh=config["mesh"],
    log:
        f"results/logs/fe_study/mesh_{{fe_mesh}}.log",
    threads: 1
    resources:
        mem_mb=4000,
    script:
        "../scripts/fe_study_mesh.py"


rule fe_reference:
    input:
        mesh=fe_study_mesh(FE_REFERENCE_MESH),
    output:
        f"{FE_STUDY_DIR}/reference/c1={{c1}}_phi={{phi}}_theta={{theta}}.h5",
    params:
        config=FE_STUDY_BASE_CONFIG,
        reference=FE_STUDY["reference"],
    log:
        "results/logs/fe_study/reference_c1={c1}_phi={phi}_theta={theta}.log",
    benchmark:
        "results/benchmarks/fe_study/reference_c1={c1}_phi={phi}_theta={theta}.tsv"
    # One reference at a time, on every core (multi-threaded BLAS): a solve of its 389k
    # unknowns peaks at 12-13 GB, and two 308k-unknown solves at once exhausted a 24 GB machine.
    threads: all_cores()
    resources:
        mem_mb=16000,
    script:
        "../scripts/fe_reference.py"


rule fe_clinical:
    input:
        mesh=MESH,
        reference_mesh=fe_study_mesh(FE_REFERENCE_MESH),
        references=fe_references,
    output:
        FE_CLINICAL_JSON,
    params:
        config={key: config[key] for key in ("fe", "material", "mesh")},
        clinical=config["clinical"],
        study=FE_STUDY["clinical"],
    log:
        "results/logs/fe_study/clinical.log",
    # All of Snakemake's cores, so that no other job of this run shares the machine
    # while the timings are taken; the solve itself is single-threaded (one core).
    threads: all_cores()
    resources:
        mem_mb=4000,
    script:
        "../scripts/fe_clinical.py"


rule fe_variant:
    input:
        mesh=fe_variant_mesh,
        reference_mesh=fe_study_mesh(FE_REFERENCE_MESH),
        references=fe_references,
    output:
        f"{FE_STUDY_DIR}/speed_accuracy/{{fe_variant}}.json",
    params:
        config=FE_STUDY_BASE_CONFIG,
        clinical=config["clinical"],
        max_dofs=FE_STUDY["speed_accuracy"]["max_dofs"],
    log:
        f"results/logs/fe_study/variant_{{fe_variant}}.log",
    threads: all_cores()  # timed: run alone (see fe_clinical)
    resources:
        mem_mb=8000,
    script:
        "../scripts/fe_variant.py"


rule fe_speed_accuracy:
    input:
        expand(f"{FE_STUDY_DIR}/speed_accuracy/{{fe_variant}}.json", fe_variant=[v.id for v in FE_VARIANTS]),
    output:
        FE_SPEED_ACCURACY_JSON,
    params:
        target=FE_STUDY["speed_accuracy"]["target"],
        default_variant=fe_default_variant(),
    log:
        "results/logs/fe_study/speed_accuracy.log",
    threads: 1
    script:
        "../scripts/fe_speed_accuracy.py"


rule fe_stability:
    input:
        mesh=fe_study_mesh(FE_STABILITY_MESH),
    output:
        FE_STABILITY_JSON,
    params:
        config={key: config[key] for key in ("fe", "material", "mesh")},
        stability=FE_STUDY["stability"],
    log:
        "results/logs/fe_study/stability.log",
    threads: 1
    resources:
        mem_mb=4000,
    script:
        "../scripts/fe_stability.py"

# The corpus of anatomies (meshes.corpus, studies.fe_study.corpus): six geometries the project makes
# itself, from the config's breast to a scan-like surface in scanner axes and a volume mesh in
# another axis convention, each imported as a user's file would be, then solved with the
# config's solver and with exact Newton. A benchmark of the import and the solver on more than
# one mesh; `snakemake -j2 corpus` runs it alone, the report shows its table. A stopped
# solve job keeps its finished solves (progress.jsonl) and a rerun resumes there.
wildcard_constraints:
    anatomy="|".join(CORPUS_ANATOMIES),


rule corpus:
    input:
        CORPUS_JSON,


rule corpus_mesh:
    output:
        xdmf=f"{CORPUS_DIR}/{{anatomy}}/mesh.xdmf",
        h5=f"{CORPUS_DIR}/{{anatomy}}/mesh.h5",
        quality=f"{CORPUS_DIR}/{{anatomy}}/quality.json",
        png=f"{CORPUS_DIR}/{{anatomy}}/mesh.png",
        section=f"{CORPUS_DIR}/{{anatomy}}/mesh.yaml",
        inputs=directory(f"{CORPUS_DIR}/{{anatomy}}/input"),
    params:
        mesh=CONFIG.section("mesh"),
        import_size=CONFIG.section("corpus", "import_size"),
    log:
        f"results/logs/corpus/mesh_{{anatomy}}.log",
    threads: 1
    resources:
        mem_mb=4000,
    conda:
        ENV
    script:
        "../scripts/corpus_mesh.py"


rule corpus_solve:
    input:
        mesh=f"{CORPUS_DIR}/{{anatomy}}/mesh.xdmf",
        quality=f"{CORPUS_DIR}/{{anatomy}}/quality.json",
        section=f"{CORPUS_DIR}/{{anatomy}}/mesh.yaml",
    output:
        f"{CORPUS_DIR}/{{anatomy}}/solves.json",
    params:
        config=CONFIG.sections_of("fe", "material"),
        clinical=CONFIG.section("clinical"),
        soft_C1=CONFIG.section("corpus", "soft_C1"),
        soft_phi=CONFIG.section("corpus", "soft_phi"),
        # each solve as it finishes: a stopped job resumes there (studies.fe_study.corpus.Progress)
        progress=lambda wildcards: f"{CORPUS_DIR}/{wildcards.anatomy}/progress.jsonl",
    log:
        f"results/logs/corpus/solve_{{anatomy}}.log",
    benchmark:
        f"results/benchmarks/corpus/solve_{{anatomy}}.tsv"
    threads: 1
    resources:
        mem_mb=6000,
    conda:
        ENV
    script:
        "../scripts/corpus_solve.py"


rule corpus_table:
    input:
        expand(f"{CORPUS_DIR}/{{anatomy}}/solves.json", anatomy=CORPUS_ANATOMIES),
    output:
        CORPUS_JSON,
    params:
        soft_C1=CONFIG.section("corpus", "soft_C1"),
        soft_phi=CONFIG.section("corpus", "soft_phi"),
    log:
        "results/logs/corpus/table.log",
    threads: 1
    conda:
        ENV
    script:
        "../scripts/corpus_table.py"

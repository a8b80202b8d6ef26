# The unloaded reference state of an imaged shape (fem.reference, studies.reference_roundtrip):
# the round trip on the config's mesh, the estimate from a loaded shape beside the naive
# prediction that takes the loaded shape as stress-free. `snakemake -j2 reference_roundtrip`
# runs it alone; the report shows its table.


rule reference_roundtrip:
    input:
        mesh=MESH,
    output:
        REFERENCE_ROUNDTRIP_JSON,
    params:
        fe=CONFIG.solve_fe,
        material=CONFIG.section("material"),
        fixed=CONFIG.section("mesh", "fixed"),
        reference_state=CONFIG.section("reference_state"),
    log:
        "results/logs/reference/roundtrip.log",
    benchmark:
        "results/benchmarks/reference/roundtrip.tsv"
    threads: 1
    resources:
        mem_mb=3000,
    conda:
        ENV
    script:
        "../scripts/reference_roundtrip.py"

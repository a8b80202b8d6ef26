rule mesh:
    output:
        xdmf=MESH,
        h5=MESH.replace(".xdmf", ".h5"),
        quality="results/mesh/quality.json",
    params:
        mesh=config["mesh"],
    log:
        "results/logs/mesh.log",
    benchmark:
        "results/benchmarks/mesh.tsv"
    threads: 1
    resources:
        mem_mb=2000,
    script:
        "../scripts/mesh.py"

rule train:
    input:
        dataset=DATASET,
    output:
        model=MODEL,
        params="results/surrogate/model/params.npz",
        history="results/surrogate/model/history.json",
    params:
        surrogate=config["surrogate"],
    log:
        "results/logs/train.log",
    benchmark:
        "results/benchmarks/train.tsv"
    threads: 2
    resources:
        mem_mb=6000,
    script:
        "../scripts/train.py"

rule report:
    input:
        dataset=DATASET,
        model=MODEL,
        history="results/surrogate/model/history.json",
        quality="results/mesh/quality.json",
    output:
        html=REPORT,
    params:
        clinical=config["clinical"],
    log:
        "results/logs/report.log",
    threads: 1
    resources:
        mem_mb=4000,
    script:
        "../scripts/report.py"

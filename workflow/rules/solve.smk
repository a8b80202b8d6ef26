rule solve:
    input:
        mesh=MESH,
    output:
        summary=f"{CASE_DIR}/summary.json",
        points=f"{CASE_DIR}/points.h5",
        fields=f"{CASE_DIR}/fields.xdmf",
        fields_h5=f"{CASE_DIR}/fields.h5",
    params:
        fe=FE_SOLVE,
        material=config["material"],
        fixed=config["mesh"]["fixed"],
    log:
        "results/logs/solve/c1={c1}_phi={phi}_theta={theta}.log",
    benchmark:
        "results/benchmarks/solve/c1={c1}_phi={phi}_theta={theta}.tsv"
    threads: 1
    resources:
        mem_mb=3000,
    script:
        "../scripts/solve_case.py"


# FE cases outside the sweep (the surrogate's extrapolation study): the same job, in their own
# folders, so that `solve` stays exactly the sweep and they never enter the dataset.
use rule solve as solve_outside with:
    output:
        summary=f"{OUTSIDE_DIR}/summary.json",
        points=f"{OUTSIDE_DIR}/points.h5",
        fields=f"{OUTSIDE_DIR}/fields.xdmf",
        fields_h5=f"{OUTSIDE_DIR}/fields.h5",
    log:
        "results/logs/solve_outside/c1={c1}_phi={phi}_theta={theta}.log",
    benchmark:
        "results/benchmarks/solve_outside/c1={c1}_phi={phi}_theta={theta}.tsv"

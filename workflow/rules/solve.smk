# One FE case: the breast under gravity at one (C1, Phi, theta), in its own folder.


rule solve:
    input:
        mesh=MESH,
    output:
        summary=f"{CASE_DIR}/summary.json",
        points=f"{CASE_DIR}/points.h5",
        fields=f"{CASE_DIR}/fields.xdmf",
        fields_h5=f"{CASE_DIR}/fields.h5",
    params:
        # `fe` with a `chest` contact obstacle written out: the job needs no mesh section
        fe=CONFIG.solve_fe,
        material=CONFIG.section("material"),
        fixed=CONFIG.section("mesh", "fixed"),
    log:
        "results/logs/solve/c1={c1}_phi={phi}_theta={theta}.log",
    benchmark:
        "results/benchmarks/solve/c1={c1}_phi={phi}_theta={theta}.tsv"
    threads: 1
    resources:
        mem_mb=3000,
    conda:
        ENV
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

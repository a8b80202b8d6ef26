# One FE case: the breast under gravity at one (C1, Phi, theta), in its own folder.
#
# With sweep.chains (the default), the sweep's cases of one gravity direction are one job,
# `solve_chain`: every C1 value of the sweep, the stiffest first, each case from its
# neighbours' solutions (fem.chain), every case still written to its own folder. Asking for a
# sweep case's file runs its direction's chain (with sweep.adaptive, any direction's: the
# rounds choose theirs as the run goes, sweep.smk); `solve` runs any other case (and every case
# with chains off) alone, from rest.
#
# The case's files are update() outputs: Snakemake keeps a case's previous files while it is
# solved again (fem.io.CaseWriter replaces them at the end, summary.json last) and restores them
# if the solve fails. A rerun that is killed thus leaves the folder whole, as the dataset built
# from it expects, and marked incomplete, so the next run solves it again (rerun-incomplete).


rule solve:
    input:
        mesh=MESH,
    output:
        summary=update(f"{CASE_DIR}/summary.json"),
        points=update(f"{CASE_DIR}/points.h5"),
        fields=update(f"{CASE_DIR}/fields.xdmf"),
        fields_h5=update(f"{CASE_DIR}/fields.h5"),
    params:
        # the solver's settings (run.config.solver_settings builds them): `fe` with a `chest`
        # contact obstacle written out (the job needs no mesh section), `material`, `mesh.fixed`
        **CONFIG.solver_params,
    log:
        f"results/logs/solve/{CASE_WILDCARDS}.log",
    benchmark:
        f"results/benchmarks/solve/{CASE_WILDCARDS}.tsv"
    threads: 1
    resources:
        mem_mb=3000,
    conda:
        ENV
    script:
        "../scripts/solve_case.py"


# solve_chain (common.smk: CHAIN_RULES, one rule), preferred to `solve` for the cases it
# writes. (The loop stands at the top level: Snakemake records a rule's `script` line with its
# indentation as its code, and reruns every case already solved when that changes.)
for chain_rule in CHAIN_RULES if CONFIG.chains else ():

    rule:
        name:
            chain_rule.name
        input:
            mesh=MESH,
        output:
            summaries=update(chain_files("summary.json", chain_rule.c1s)),
            points=update(chain_files("points.h5", chain_rule.c1s)),
            fields=update(chain_files("fields.xdmf", chain_rule.c1s)),
            fields_h5=update(chain_files("fields.h5", chain_rule.c1s)),
        params:
            **CONFIG.solver_params,
        wildcard_constraints:
            direction=chain_rule.direction,
        log:
            "results/logs/solve_chain/{direction}.log",
        benchmark:
            "results/benchmarks/solve_chain/{direction}.tsv"
        # the sweep, the dataset, the selected model and the 3D view before the longer studies
        priority: 50
        threads: 1
        resources:
            mem_mb=3000,
        conda:
            ENV
        script:
            "../scripts/solve_chain.py"

    workflow.ruleorder(chain_rule.name, "solve")


# FE cases outside the sweep (the surrogate's extrapolation study): the same job, in their own
# folders, so that `solve` stays exactly the sweep and they never enter the dataset.
use rule solve as solve_outside with:
    output:
        summary=update(f"{OUTSIDE_DIR}/summary.json"),
        points=update(f"{OUTSIDE_DIR}/points.h5"),
        fields=update(f"{OUTSIDE_DIR}/fields.xdmf"),
        fields_h5=update(f"{OUTSIDE_DIR}/fields.h5"),
    log:
        f"results/logs/solve_outside/{CASE_WILDCARDS}.log",
    benchmark:
        f"results/benchmarks/solve_outside/{CASE_WILDCARDS}.tsv"

# The adaptive sweep's rounds (sweep.adaptive; fem.adaptive, docs/sweep.md).
#
# The start design (sweep.C1_kPa x its directions) is solved as any sweep is (solve.smk). Round
# k is a checkpoint: from every case solved before it, it estimates where the error between the
# cases is largest and writes results/sweep/round_<k>.json, the directions it adds (each solved
# at every C1 value as one chain) or that the sweep is done. Once a round is written, the
# workflow asks for its cases and, after them, for the next round. An interrupted run resumes
# at the round it was in: the plans written and the chains solved are kept.


if ADAPTIVE is not None:

    checkpoint sweep_round:
        input:
            summaries=lambda wildcards: [case_file(c, "summary.json")
                                         for c in sweep_cases_through(int(wildcards.round) - 1)[0]],
            points=lambda wildcards: [case_file(c, "points.h5")
                                      for c in sweep_cases_through(int(wildcards.round) - 1)[0]],
        output:
            SWEEP_ROUND,
        params:
            sweep=CONFIG.section("sweep"),
            # the extrapolation study's directions stay unseen: no round adds them
            reserved=sorted({(c.phi, c.theta) for c in CONFIG.surrogate_study.extrapolation}),
        wildcard_constraints:
            round="[1-9][0-9]*",
        log:
            "results/logs/sweep_round/{round}.log",
        benchmark:
            "results/benchmarks/sweep_round/{round}.tsv"
        # the sweep before the studies
        priority: 50
        threads: 1
        resources:
            mem_mb=3000,
        conda:
            ENV
        script:
            "../scripts/sweep_round.py"

    # Every round's plan in one record, for the report: how the estimate fell, round by round.
    rule sweep_rounds:
        input:
            sweep_rounds,
        output:
            SWEEP_ROUNDS_JSON,
        params:
            # the target and the budget the rounds stopped by, beside them in the record
            settings=ADAPTIVE.settings,
        log:
            "results/logs/sweep_rounds.log",
        conda:
            ENV
        script:
            "../scripts/sweep_rounds.py"


# Whether the sweep's error estimate finds where the surrogate errs (studies.sweep.sweep_estimate):
# at the random cases off the grid and at the held-out splits' test cases, the estimate beside
# the true error of the model that did not train on them.
SWEEP_ESTIMATE_SPLITS = [s for s in ("by_direction", "by_case") if s in CONFIG.held_out_splits]


rule sweep_estimate:
    input:
        dataset=DATASET,
        off_grid=OFF_GRID_JSON,
        off_grid_points=off_grid_files("points.h5"),
        held_out=[f"{SURROGATE_DIR}/model_{s}/model.json" for s in SWEEP_ESTIMATE_SPLITS],
        held_out_arrays=[f"{SURROGATE_DIR}/model_{s}/params.npz" for s in SWEEP_ESTIMATE_SPLITS],
    output:
        SWEEP_ESTIMATE_JSON,
    log:
        "results/logs/sweep_estimate.log",
    threads: 1
    resources:
        mem_mb=3000,
    conda:
        ENV
    script:
        "../scripts/sweep_estimate.py"

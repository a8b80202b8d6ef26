# The unloaded reference state of an imaged shape (fem.reference, studies.reference_state.reference_roundtrip):
# the round trip on the config's mesh, the estimate from a loaded shape beside the naive
# prediction that takes the loaded shape as stress-free. `snakemake -j2 reference_roundtrip`
# runs it alone; the report shows its table. With reference_state.imaged, the chain from the
# imaged mesh: its reference (the workflow's MESH), points tracked by FE and by the surrogate,
# the stiffness from a second observation.


rule reference_roundtrip:
    input:
        mesh=MESH,
    output:
        REFERENCE_ROUNDTRIP_JSON,
    params:
        **CONFIG.solver_params,
        # the round trip's own keys: the imaged chain's do not rerun it
        reference_state={
            key: CONFIG.section("reference_state", key)
            for key in ("C1_kPa", "observed_phi", "tolerance_mm")
        },
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


if IMAGED is not None:

    rule reference_state:
        input:
            imaged=IMAGED_MESH,
        output:
            xdmf=MESH,
            h5=MESH.replace(".xdmf", ".h5"),
            record=REFERENCE_RECORD,
        params:
            **CONFIG.solver_params,
            imaged=CONFIG.section("reference_state", "imaged"),
            tolerance_mm=CONFIG.section("reference_state", "tolerance_mm"),
        log:
            "results/logs/reference/state.log",
        benchmark:
            "results/benchmarks/reference/state.tsv"
        threads: 1
        resources:
            mem_mb=3000,
        conda:
            ENV
        script:
            "../scripts/reference_state.py"

    rule tracking:
        wildcard_constraints:
            name="|".join(IMAGED.points) or "(?!)",
        input:
            imaged=IMAGED_MESH,
            reference=MESH,
            model=MODEL,
            model_arrays=MODEL_ARRAYS,
            points=lambda w: IMAGED.point_files[w.name],
        output:
            csv="results/tracking/{name}.csv",
            json="results/tracking/{name}.json",
        params:
            **CONFIG.solver_params,
            mesh=CONFIG.section("mesh"),
            target=lambda w: {"C1": IMAGED.points[w.name].C1, "phi": IMAGED.points[w.name].phi,
                              "theta": IMAGED.points[w.name].theta},
        log:
            "results/logs/reference/tracking_{name}.log",
        threads: 1
        resources:
            mem_mb=3000,
        conda:
            ENV
        script:
            "../scripts/tracking.py"

    rule stiffness:
        input:
            reference=MESH,
            model=MODEL,
            model_arrays=MODEL_ARRAYS,
            observation=IMAGED.observation or [],
        output:
            json=STIFFNESS_JSON,
            png="results/stiffness/misfit.png",
        params:
            **CONFIG.solver_params,
            mesh=CONFIG.section("mesh"),
            # the observation's posture (Phi, theta), degrees
            posture=[IMAGED.observed_in.phi, IMAGED.observed_in.theta]
            if IMAGED.observed_in
            else [],
        log:
            "results/logs/reference/stiffness.log",
        benchmark:
            "results/benchmarks/reference/stiffness.tsv"
        threads: 1
        resources:
            mem_mb=3000,
        conda:
            ENV
        script:
            "../scripts/stiffness.py"

# The sweep's cases gathered into one HDF5 dataset with its reproducible splits.
#
# The dataset is an update() output: Snakemake keeps the previous one while it is rebuilt (the new
# one is written to a temporary file and renamed) and restores it if the rebuild fails, e.g. on a
# case file that aggregation refuses, so a bad case file costs no dataset. The restored file is
# newer than the refused input, so after such a failure the run's end marks it out of date
# (run.workdir.age_refused): the next run refuses again until the input is fixed.


onerror:
    age_refused(DATASET)


rule aggregate:
    input:
        summaries=case_files("summary.json"),
        points=case_files("points.h5"),
        # on a quadratic mesh, the fields at every node (a pod surrogate's modes between points)
        fields=case_files("fields.h5"),
        # its tetrahedra go into the dataset (a pod surrogate interpolates its modes in them)
        mesh=MESH,
    output:
        update(DATASET),
    params:
        dataset=CONFIG.section("dataset"),
        # the by-case split holds these setups out as test cases
        clinical=CONFIG.section("clinical"),
        # Provenance: only the sections the data depend on, so that e.g. a surrogate
        # setting does not rebuild the dataset.
        provenance=CONFIG.sections_of("mesh", "material", "fe", "sweep", "dataset"),
    log:
        "results/logs/aggregate.log",
    benchmark:
        "results/benchmarks/aggregate.tsv"
    priority: 50
    threads: 1
    resources:
        mem_mb=4000,
    conda:
        ENV
    script:
        "../scripts/aggregate.py"

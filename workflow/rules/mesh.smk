# Geometry and meshing: the parametric breast, or a user's surface / volume mesh.


rule mesh:
    input:
        # an imported geometry (and any surface a boundary rule measures from) is an input,
        # so that editing the file rebuilds the mesh; the parametric source has none
        sources=CONFIG.mesh.input_files(),
    output:
        # the imaged shape when reference_state.imaged is set (rule reference_state makes MESH)
        xdmf=BUILT_MESH,
        h5=BUILT_MESH.replace(".xdmf", ".h5"),
        quality="results/mesh/quality.json",
        png="results/mesh/mesh.png",
    params:
        mesh=CONFIG.section("mesh"),
    log:
        "results/logs/mesh.log",
    benchmark:
        "results/benchmarks/mesh.tsv"
    threads: 1
    resources:
        mem_mb=2000,
    conda:
        ENV
    script:
        "../scripts/mesh.py"

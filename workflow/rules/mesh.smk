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


# The skin's pairs that face each other at rest on the mesh the cases solve on (a sharp
# chest-wall rim, a thin region, a crease): what fe.self_contact.at_rest treats, so that
# nothing touches at rest. The report's mesh section shows them beside the mesh's quality.
rule self_contact_at_rest:
    input:
        mesh=MESH,
    output:
        json="results/mesh/self_contact_at_rest.json",
    params:
        fe=CONFIG.fe_self_contact,
    log:
        "results/logs/self_contact_at_rest.log",
    threads: 1
    resources:
        mem_mb=2000,
    conda:
        ENV
    script:
        "../scripts/self_contact_at_rest.py"

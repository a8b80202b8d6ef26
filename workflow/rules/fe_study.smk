# FE study (issue 4): the clinical benchmark (time, factorisation equivalents, a fixed-step
# baseline, accuracy against a refined reference), speed against accuracy over mesh sizes x
# elements x solver presets, and stability maps over (C1, Phi) for adaptive and fixed-step
# loading. Benchmarks, not tests: `snakemake -j2 fe_study` runs them alone; the report needs
# them. The library code is fem.benchmark and fem.stability; JSON results land in
# results/fe_study/.
from fem.benchmark import MESH_ID_PATTERN, VARIANT_ID_PATTERN, MeshSpec, Variant, clinical_cases, expand_variants
from fem.exceptions import FEError

FE_STUDY = config["fe_study"]
FE_STUDY_DIR = "results/fe_study"
FE_CLINICAL_JSON = f"{FE_STUDY_DIR}/clinical.json"
FE_SPEED_ACCURACY_JSON = f"{FE_STUDY_DIR}/speed_accuracy.json"
FE_STABILITY_JSON = f"{FE_STUDY_DIR}/stability.json"
FE_STUDY_RESULTS = [FE_CLINICAL_JSON, FE_SPEED_ACCURACY_JSON, FE_STABILITY_JSON]

try:
    FE_CLINICAL_CASES = clinical_cases(config["clinical"])
    FE_REFERENCE_MESH = MeshSpec.from_mapping(FE_STUDY["reference"]["mesh"])
    FE_VARIANTS = expand_variants(FE_STUDY["speed_accuracy"]["variants"])
    FE_STABILITY_MESH = MeshSpec.from_mapping(FE_STUDY["stability"]["mesh"])
    # what the reference and the variants depend on: not the default's discretisation
    FE_STUDY_BASE_CONFIG = Variant.base_config(config)
except (FEError, KeyError, TypeError, ValueError) as err:
    raise WorkflowError(f"invalid configuration: fe_study: {err}") from None


def fe_study_mesh(spec):
    """Path of the study mesh with sizes ``spec`` (a MeshSpec)."""
    return f"{FE_STUDY_DIR}/meshes/{spec.id}/mesh.xdmf"


def fe_references(wildcards=None):
    """The reference displacement of every clinical case (input function: only a run that
    needs the FE study requires the `clinical` list to be non-empty)."""
    if not FE_CLINICAL_CASES:
        raise WorkflowError("invalid configuration: the FE study needs at least one case in `clinical`")
    return [f"{FE_STUDY_DIR}/reference/{case.id}.h5" for case in FE_CLINICAL_CASES]


def fe_default_variant():
    """Id of the study variant that the workflow's own mesh and fe settings amount to."""
    size, disc = config["mesh"]["size"], config["fe"]["discretisation"]
    degree = disc["degree"]
    element = "p1-penalty" if disc["element"] == "p1-penalty" else f"p{degree}p{degree - 1}"
    spec = MeshSpec.from_mapping(size)
    return Variant(spec, element, config["fe"]["solver"], disc["quadrature_degree"]).id


def fe_variant_mesh(wildcards):
    """The study mesh of the variant in ``wildcards``."""
    return fe_study_mesh(Variant.from_id(wildcards.variant).mesh)


wildcard_constraints:
    fe_mesh=MESH_ID_PATTERN,
    variant=VARIANT_ID_PATTERN,


rule fe_study:
    input:
        FE_STUDY_RESULTS,


rule fe_study_mesh:
    output:
        xdmf=f"{FE_STUDY_DIR}/meshes/{{fe_mesh}}/mesh.xdmf",
        h5=f"{FE_STUDY_DIR}/meshes/{{fe_mesh}}/mesh.h5",
        quality=f"{FE_STUDY_DIR}/meshes/{{fe_mesh}}/quality.json",
        png=f"{FE_STUDY_DIR}/meshes/{{fe_mesh}}/mesh.png",
    params:
        mesh=config["mesh"],
    log:
        f"results/logs/fe_study/mesh_{{fe_mesh}}.log",
    threads: 1
    resources:
        mem_mb=4000,
    script:
        "../scripts/fe_study_mesh.py"


rule fe_reference:
    input:
        mesh=fe_study_mesh(FE_REFERENCE_MESH),
    output:
        f"{FE_STUDY_DIR}/reference/c1={{c1}}_phi={{phi}}_theta={{theta}}.h5",
    params:
        config=FE_STUDY_BASE_CONFIG,
        reference=FE_STUDY["reference"],
    log:
        "results/logs/fe_study/reference_c1={c1}_phi={phi}_theta={theta}.log",
    benchmark:
        "results/benchmarks/fe_study/reference_c1={c1}_phi={phi}_theta={theta}.tsv"
    # One reference at a time, on every core (multi-threaded BLAS): a solve of its 389k
    # unknowns peaks at 12-13 GB, and two 308k-unknown solves at once exhausted a 24 GB machine.
    threads: all_cores()
    resources:
        mem_mb=16000,
    script:
        "../scripts/fe_reference.py"


rule fe_clinical:
    input:
        mesh=MESH,
        reference_mesh=fe_study_mesh(FE_REFERENCE_MESH),
        references=fe_references,
    output:
        FE_CLINICAL_JSON,
    params:
        config={key: config[key] for key in ("fe", "material", "mesh")},
        clinical=config["clinical"],
        study=FE_STUDY["clinical"],
    log:
        "results/logs/fe_study/clinical.log",
    # All of Snakemake's cores, so that no other job of this run shares the machine
    # while the timings are taken; the solve itself is single-threaded (one core).
    threads: all_cores()
    resources:
        mem_mb=4000,
    script:
        "../scripts/fe_clinical.py"


rule fe_variant:
    input:
        mesh=fe_variant_mesh,
        reference_mesh=fe_study_mesh(FE_REFERENCE_MESH),
        references=fe_references,
    output:
        f"{FE_STUDY_DIR}/speed_accuracy/{{variant}}.json",
    params:
        config=FE_STUDY_BASE_CONFIG,
        clinical=config["clinical"],
        max_dofs=FE_STUDY["speed_accuracy"]["max_dofs"],
    log:
        f"results/logs/fe_study/variant_{{variant}}.log",
    threads: all_cores()  # timed: run alone (see fe_clinical)
    resources:
        mem_mb=8000,
    script:
        "../scripts/fe_variant.py"


rule fe_speed_accuracy:
    input:
        expand(f"{FE_STUDY_DIR}/speed_accuracy/{{variant}}.json", variant=[v.id for v in FE_VARIANTS]),
    output:
        FE_SPEED_ACCURACY_JSON,
    params:
        target=FE_STUDY["speed_accuracy"]["target"],
        default_variant=fe_default_variant(),
    log:
        "results/logs/fe_study/speed_accuracy.log",
    threads: 1
    script:
        "../scripts/fe_speed_accuracy.py"


rule fe_stability:
    input:
        mesh=fe_study_mesh(FE_STABILITY_MESH),
    output:
        FE_STABILITY_JSON,
    params:
        config={key: config[key] for key in ("fe", "material", "mesh")},
        stability=FE_STUDY["stability"],
    log:
        "results/logs/fe_study/stability.log",
    threads: 1
    resources:
        mem_mb=4000,
    script:
        "../scripts/fe_stability.py"

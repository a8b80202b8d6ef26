"""Snakemake adapter: the surrogate's goals measured in one job, FE and surrogate on one core."""

import json
import logging
from pathlib import Path

from fem.parameters import SolverSettings
from fem.sweep import clinical_cases
from studies.results import write_json
from studies.surrogate_benchmark import format_benchmark, run_benchmark

logging.basicConfig(filename=snakemake.log[0], level=logging.INFO, force=True)

settings = SolverSettings.from_config(
    {
        "fe": snakemake.params.fe,
        "material": snakemake.params.material,
        "mesh": {"fixed": snakemake.params.fixed},
    }
)
cases = clinical_cases(snakemake.params.clinical)
bench = run_benchmark(
    Path(snakemake.input.model).parent,
    snakemake.input.mesh,
    cases,
    settings,
    json.loads(Path(snakemake.input.table).read_text()),
    json.loads(Path(snakemake.input.clinical).read_text()),
    repeats=snakemake.params.repeats,
)
bench["variants"] = json.loads(Path(snakemake.input.variants).read_text())
write_json(snakemake.output[0], bench)
text = format_benchmark(bench)
logging.getLogger("benchmark").info("\n%s", text)
print(text, flush=True)

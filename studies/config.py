"""The workflow's configuration, validated once against its schema and parsed into typed objects.

:meth:`WorkflowConfig.from_mapping` is the one place that reads ``config.yaml``: it checks the
mapping against ``workflow/schemas/config.schema.yaml`` (which also fills the defaults), sorts
every mapping's keys and builds the objects of every layer from it: the mesh
(:class:`meshes.config.MeshConfig`), the solve jobs' FE settings
(:class:`fem.parameters.SolverSettings`), the sweep and the clinical cases
(:mod:`fem.sweep`), the FE study (:mod:`studies.fe_variants`) and the surrogate with its study
(:class:`surrogate.config.SurrogateConfig`). It lives in ``studies/`` because it spans them all.

The schema states every bound and default; the dataclasses check what they need to stay
valid on their own, and ``tests/test_config.py`` keeps the bounds they repeat in step with it.
Snakemake records a rule's ``params`` by their text, so the mappings the rules pass on come from
:meth:`WorkflowConfig.section`, the validated mapping itself, not rebuilt from the objects.
"""

from __future__ import annotations

import copy
import sys
from collections.abc import Iterator, Mapping
from contextlib import contextmanager
from dataclasses import dataclass
from pathlib import Path
from typing import Any

import jsonschema
import numpy as np
from jsonschema import validators

from fem.configfile import ConfigFileError
from fem.configfile import read_config_file as fem_read_config_file
from fem.contact import resolve_obstacle
from fem.dataset import SplitFractions, direction_keys
from fem.exceptions import FEError
from fem.parameters import SolverSettings
from fem.sweep import Case, clinical_cases, random_cases, sweep_cases
from meshes.config import MeshConfig, size_for_source
from meshes.parametric import BreastGeometry
from meshes.schema import SCHEMA_PATH, load_schema, schema_errors
from studies.fe_variants import MeshSpec, Variant, expand_variants
from surrogate.config import SurrogateConfig, SurrogateConfigError, parse_architecture


class ConfigError(ValueError):
    """The configuration is invalid; the message names each offending key (dotted path).

    Attributes:
        problems: one ``dotted.key: message`` (or ``dotted.key message``) per problem.
    """

    def __init__(self, *problems: str) -> None:
        super().__init__(*problems)
        self.problems = problems

    def __str__(self) -> str:
        if len(self.problems) == 1:
            return self.problems[0]
        return f"{len(self.problems)} problems:" + "".join(f"\n  {p}" for p in self.problems)


def read_config_file(path: str | Path) -> dict[str, Any]:
    """A config file (YAML) as a mapping (:func:`fem.configfile.read_config_file`).

    Raises:
        ConfigError: for a file that cannot be read, is not YAML (with the line and column
            where the parser stopped), or does not hold a mapping of sections.
    """
    try:
        return fem_read_config_file(path)
    except ConfigFileError as err:
        raise ConfigError(str(err)) from None


def _with_defaults(validator_class: type) -> type:
    """``validator_class`` that also writes each property's ``default`` into the instance.

    The recipe of the jsonschema FAQ, as ``snakemake.utils.validate`` applies it, so that a
    config filled here equals one filled by Snakemake.
    """
    validate_properties = validator_class.VALIDATORS["properties"]

    def set_defaults(validator, properties, instance, schema):
        for name, subschema in properties.items():
            if "default" in subschema and isinstance(instance, dict):
                instance.setdefault(name, subschema["default"])
        yield from validate_properties(validator, properties, instance, schema)

    return validators.extend(validator_class, {"properties": set_defaults})


def canonical(value: Any) -> Any:
    """``value`` with every mapping's keys sorted, recursively.

    Snakemake compares a rule's params with the last run's by their text, in which a mapping's
    key order shows; sorting makes two configs that differ only in key order (a file rewritten
    by a tool, keys moved by hand) the same experiment.
    """
    if isinstance(value, dict):
        return {key: canonical(value[key]) for key in sorted(value)}
    if isinstance(value, list):
        return [canonical(item) for item in value]
    return value


def validated(config: Mapping[str, Any], schema_path: str | Path = SCHEMA_PATH) -> dict[str, Any]:
    """``config`` checked against the schema, with its defaults filled and its keys sorted.

    Raises:
        ConfigError: listing every violation, each as ``dotted.key: message``.
    """
    schema = load_schema(schema_path)
    problems = schema_errors(config, schema)
    if problems:
        raise ConfigError(*problems)
    filled = copy.deepcopy(dict(config))
    # the defaults filled in are the schema's own objects: this call's schema, used once
    _with_defaults(jsonschema.Draft202012Validator)(schema).validate(filled)
    return canonical(filled)


def _named(key: str, text: str, subkeys: tuple[str, ...] = ()) -> str:
    """``text``, an error of config key ``key``, beginning with its full dotted key.

    The libraries' messages mostly name their key already, from the section down
    ("surrogate.width must ...") or from a sub-section ("geometry.axilla_angle must ..." of
    ``mesh.geometry``, "loading.min_step must ..." of ``fe`` with sub-key ``loading``): those
    are completed, the others prefixed with ``key``.
    """
    if text.startswith(key):
        return text
    parent, _, last = key.rpartition(".")
    if parent and text.startswith(f"{last}."):
        return f"{parent}.{text}"
    if any(text.startswith(f"{sub}.") for sub in subkeys):
        return f"{key}.{text}"
    return f"{key}: {text}"


@contextmanager
def _section(key: str, subkeys: tuple[str, ...] = ()) -> Iterator[None]:
    """Turn a parsing error of config key ``key`` into a :class:`ConfigError` that names it."""
    try:
        yield
    except ConfigError:
        raise
    except (FEError, ValueError, KeyError, TypeError) as err:
        text = f"missing key {err}" if isinstance(err, KeyError) else str(err)
        raise ConfigError(_named(key, text, subkeys)) from None


def default_variant(mesh: Mapping[str, Any], fe: Mapping[str, Any]) -> Variant:
    """The FE-study variant that the workflow's own ``mesh`` and ``fe`` sections amount to."""
    disc = fe["discretisation"]
    degree = disc["degree"]
    element = "p1-penalty" if disc["element"] == "p1-penalty" else f"p{degree}p{degree - 1}"
    size = size_for_source(mesh.get("source", "parametric"), mesh["size"])
    return Variant(MeshSpec.from_mapping(size), element, fe["solver"], disc["quadrature_degree"])


def check_sweep_splits(cases: tuple[Case, ...], clinical: tuple[Case, ...],
                       split: SplitFractions) -> None:
    """Refuse a sweep too small for the dataset's by-case split to fill its parts.

    The clinical cases always go to the test part; of the other cases the split needs one to
    train on, one to validate on and (with a test fraction) one more to test on.

    Raises:
        ValueError: naming how many cases there are, and the smallest sweep that works.
    """
    free = len(set(cases) - set(clinical))
    needed = 3 if split.test > 0 else 2
    if free < needed:
        raise ValueError(
            f"{len(cases)} cases, {len(cases) - free} of them clinical (held out as test): the "
            f"dataset's by-case split needs at least {needed} other cases (train, validation"
            f"{', test' if split.test > 0 else ''}); give the sweep at least "
            f"{needed + len(cases) - free} cases")


@dataclass(frozen=True, slots=True)
class FailureEdgesConfig:
    """The sweep's failed cases traced (``fe_study.failure_edges``, :mod:`studies.failure_edge`).

    Attributes:
        n: how many failed cases to trace (0: none).
        step_deg: the turn's longest step (degrees).
        resolution_deg: its shortest step before the edge is called (degrees, at most the step).
    """

    n: int
    step_deg: float
    resolution_deg: float

    def __post_init__(self) -> None:
        if self.n < 0:
            raise ValueError(f"n must be 0 or more, got {self.n}")
        if not 0 < self.resolution_deg <= self.step_deg:
            raise ValueError(f"resolution_deg ({self.resolution_deg}) must be positive and at "
                             f"most step_deg ({self.step_deg})")


@dataclass(frozen=True, slots=True)
class StabilityAuditConfig:
    """The sweep's converged cases judged (``fe_study.stability_audit``).

    See :mod:`studies.stability_audit`.

    Attributes:
        softest: how many of the sweep's C1 values to audit, softest first (0: none).
    """

    softest: int

    def __post_init__(self) -> None:
        if self.softest < 0:
            raise ValueError(f"softest must be 0 or more, got {self.softest}")


@dataclass(frozen=True, slots=True)
class FoldSectionConfig:
    """The fold cut with and without self-contact (``fe_study.fold_section``).

    See :mod:`studies.fold_section`.

    Attributes:
        cases: the named cases, each (C1 kPa, Φ deg, θ deg).
        largest: how many of the sweep's cases with the largest self-contact force to add.
    """

    cases: tuple[tuple[float, float, float], ...]
    largest: int

    def __post_init__(self) -> None:
        if self.largest < 0:
            raise ValueError(f"largest must be 0 or more, got {self.largest}")
        for case in self.cases:
            if len(case) != 3 or not np.all(np.isfinite(case)) or case[0] <= 0:
                raise ValueError(f"a case is [C1 > 0, Φ] or [C1, Φ, θ], finite; got {case}")

    @classmethod
    def from_mapping(cls, values: Mapping[str, Any]) -> FoldSectionConfig:
        """From the validated section (θ defaults to 0)."""
        return cls(tuple((float(c[0]), float(c[1]), float(c[2]) if len(c) > 2 else 0.0)
                         for c in values["cases"]), int(values["largest"]))


@dataclass(frozen=True, slots=True)
class FEStudyConfig:
    """The FE study (``fe_study``): what is compared with what.

    Attributes:
        reference: the refined discretisation every other one is compared with.
        variants: the speed-accuracy variants, sorted, each once.
        target: the accuracy target of the speed-accuracy study (relative error).
        max_dofs: variants with more unknowns are skipped, not solved.
        stability_mesh: the mesh sizes of the stability maps.
        failure_edges: how the sweep's failed cases are traced.
        stability_audit: which of the sweep's converged cases are judged for stability.
        fold_section: which cases are cut at the fold with and without self-contact.
        default_variant: the variant the workflow's own mesh and ``fe`` settings amount to.
        base_config: the ``fe``, ``material`` and ``mesh`` sections that the reference and the
            variants depend on, without the default's discretisation and solver preset, which
            each variant sets (so changing those re-solves no study case).
    """

    reference: Variant
    variants: tuple[Variant, ...]
    target: float
    max_dofs: int
    stability_mesh: MeshSpec
    failure_edges: FailureEdgesConfig
    stability_audit: StabilityAuditConfig
    fold_section: FoldSectionConfig
    default_variant: Variant
    base_config: dict[str, Any]

    @classmethod
    def from_sections(cls, sections: Mapping[str, Any]) -> FEStudyConfig:
        """Build from the validated config (``fe_study``, ``fe``, ``material``, ``mesh``)."""
        study = sections["fe_study"]
        ref = study["reference"]
        with _section("fe_study.reference"):
            reference = Variant(MeshSpec.from_mapping(ref["mesh"]), ref["element"], ref["solver"],
                                ref["quadrature_degree"])
        with _section("fe_study.speed_accuracy.variants"):
            variants = tuple(expand_variants(study["speed_accuracy"]["variants"]))
        with _section("fe_study.stability.mesh"):
            stability_mesh = MeshSpec.from_mapping(study["stability"]["mesh"])
        with _section("fe_study.failure_edges"):
            edges = study["failure_edges"]
            failure_edges = FailureEdgesConfig(edges["n"], edges["step_deg"],
                                               edges["resolution_deg"])
        with _section("fe_study.stability_audit"):
            audit = StabilityAuditConfig(study["stability_audit"]["softest"])
        with _section("fe_study.fold_section"):
            fold = FoldSectionConfig.from_mapping(study["fold_section"])
        with _section("mesh.size"):
            default = default_variant(sections["mesh"], sections["fe"])
        speed_accuracy = study["speed_accuracy"]
        return cls(reference, variants, speed_accuracy["target"], speed_accuracy["max_dofs"],
                   stability_mesh, failure_edges, audit, fold, default,
                   Variant.base_config(sections))


@dataclass(frozen=True, slots=True)
class SurrogateVariant:
    """A named variant of the surrogate settings (``surrogate_study.variants``).

    Attributes:
        name: its name, a wildcard of the workflow.
        overrides: the keys it changes, as written.
        settings: the ``surrogate`` settings with those keys changed.
    """

    name: str
    overrides: dict[str, Any]
    settings: SurrogateConfig


@dataclass(frozen=True, slots=True)
class Posture:
    """A posture a patient takes, at one stiffness (``surrogate_study.postures``).

    Attributes:
        name: as the config names it (``prone``, ``standing``, ...).
        note: what it is, in words (the 3D view's tooltip).
        case: its FE case (C1, and gravity's direction relative to the body).
        in_sweep: whether the sweep solves that case (else it is solved outside it).
    """

    name: str
    note: str
    case: Case
    in_sweep: bool

    @property
    def folder(self) -> str:
        """The case's folder under ``results/``: ``cases/<id>`` or ``outside/<id>``."""
        return f"{'cases' if self.in_sweep else 'outside'}/{self.case.id}"


def postures_of(section: Mapping[str, Any], sweep: tuple[Case, ...]) -> tuple[Posture, ...]:
    """Every (posture, C1) of the ``postures`` section, postures in its order, C1 within each.

    Raises:
        ConfigError: if two postures share a name.
    """
    directions = section.get("directions", ())
    names = [item["name"] for item in directions]
    twice = sorted({name for name in names if names.count(name) > 1})
    if twice:
        raise ConfigError(f"surrogate_study.postures names {', '.join(map(repr, twice))} twice")
    in_sweep = set(sweep)
    out = []
    for item in directions:
        for C1 in section["C1_kPa"]:
            case = Case(float(C1), float(item["phi"]), float(item.get("theta", 0.0)))
            out.append(Posture(item["name"], item.get("note", ""), case, case in in_sweep))
    return tuple(out)


def off_grid_cases(section: Mapping[str, Any], sweep: tuple[Case, ...]) -> tuple[Case, ...]:
    """The ``off_grid`` section's random cases within the sweep's range, less the sweep's own.

    ``{n, seed, part, C1_kPa: [low, high]}``: ``n`` cases drawn from ``seed``
    (:func:`fem.sweep.random_cases`), C1 between ``C1_kPa``'s ends (default: the sweep's
    softest and stiffest), gravity over ``part`` of the sphere. A draw that repeats a case or
    falls on one of the sweep's is dropped: the set is off the grid by construction.

    Raises:
        ConfigError: for a range or part that :func:`fem.sweep.random_cases` refuses.
    """
    n = int(section.get("n", 0))
    if n == 0:
        return ()
    with _section("surrogate_study.off_grid"):
        c1_range = section.get("C1_kPa") or (min(c.C1 for c in sweep), max(c.C1 for c in sweep))
        drawn = random_cases(n, int(section.get("seed", 0)), tuple(c1_range),
                             section.get("part", "caudal"))
    in_sweep = set(sweep)
    return tuple(c for c in dict.fromkeys(drawn) if c not in in_sweep)


@dataclass(frozen=True, slots=True)
class SurrogateStudyConfig:
    """The surrogate's study (``surrogate_study``).

    Attributes:
        architectures: the architectures trained, ``<layers>x<width>``, each once.
        repeats: trainings per architecture and per variant.
        variants: the named variants, in the config's (sorted) order.
        extrapolation: the FE cases of its extrapolation blocks that the sweep lacks, sorted.
        timing_repeats: timed predictions per model.
        prediction_budget_ms: the selection's time budget (None: by accuracy alone).
        postures: the clinical postures at each of their C1 values.
        off_grid: the random test cases of ``off_grid`` that the sweep lacks, in drawn order
            (:func:`off_grid_cases`).
        refit: whether the model used downstream is the selected run trained again on its
            validation data too (``select_model``), or the selected run itself.
    """

    architectures: tuple[str, ...]
    repeats: int
    variants: tuple[SurrogateVariant, ...]
    extrapolation: tuple[Case, ...]
    timing_repeats: int
    prediction_budget_ms: float | None
    postures: tuple[Posture, ...] = ()
    off_grid: tuple[Case, ...] = ()
    refit: bool = True

    @classmethod
    def from_sections(
        cls, study: Mapping[str, Any], surrogate: SurrogateConfig, sweep: tuple[Case, ...]
    ) -> SurrogateStudyConfig:
        """Build from the ``surrogate_study`` section, the surrogate settings and the sweep."""
        with _section("surrogate_study.architectures"):
            parsed = [parse_architecture(a) for a in study["architectures"]]
            if len(set(parsed)) != len(parsed):
                raise ConfigError("surrogate_study.architectures lists one twice")
        variants = []
        for name, overrides in study["variants"].items():
            with _section(f"surrogate_study.variants.{name}"):
                try:
                    settings = SurrogateConfig.from_mapping({**surrogate.as_dict(), **overrides})
                except SurrogateConfigError as err:  # named as the variant's key, not surrogate's
                    text = str(err).replace("surrogate.", f"surrogate_study.variants.{name}.", 1)
                    raise ConfigError(text) from None
            variants.append(SurrogateVariant(name, dict(overrides), settings))
        extra: set[Case] = set()
        for i, block in enumerate(study["extrapolation"]):
            with _section(f"surrogate_study.extrapolation.{i}"):
                extra.update(sweep_cases(block))
        return cls(
            architectures=tuple(f"{layers}x{width}" for layers, width in parsed),
            repeats=study["repeats"],
            variants=tuple(variants),
            extrapolation=tuple(sorted(extra - set(sweep))),
            timing_repeats=study["timing_repeats"],
            prediction_budget_ms=study["prediction_budget_ms"],
            postures=postures_of(study.get("postures") or {}, sweep),
            off_grid=off_grid_cases(study.get("off_grid") or {}, sweep),
            refit=bool(study.get("refit", True)),
        )

    def variant(self, name: str) -> SurrogateVariant:
        """The variant called ``name``."""
        for variant in self.variants:
            if variant.name == name:
                return variant
        raise KeyError(f"surrogate_study.variants has no {name!r}")


@dataclass(frozen=True, slots=True)
class ImagedConfig:
    """The mesh as an image of the loaded breast (``reference_state.imaged``) and what follows.

    Attributes:
        case: the imaged posture and the stiffness assumed for it.
        points: named points files and the case (C1 of ``case``) each is tracked to.
        point_files: the points files by name.
        observation: a second observation's file, or None.
        observed_in: its posture (C1 of ``case``), or None.
    """

    case: Case
    points: dict[str, Case]
    point_files: dict[str, str]
    observation: str | None
    observed_in: Case | None

    @classmethod
    def from_section(cls, section: Mapping[str, Any]) -> ImagedConfig | None:
        """Parse ``reference_state``; None when ``imaged`` is unset.

        Raises:
            ConfigError: for points or an observation without ``imaged``.
        """
        imaged = section.get("imaged")
        if imaged is None:
            extra = [k for k in ("points", "observation") if section.get(k)]
            if extra:
                raise ConfigError(
                    f"reference_state.{extra[0]} needs reference_state.imaged (the stiffness "
                    "and posture of the imaged mesh)"
                )
            return None
        c1 = float(imaged["C1_kPa"])
        case = Case(c1, imaged["phi"], imaged.get("theta", 0.0))
        points = {name: Case(c1, p["phi"], p.get("theta", 0.0))
                  for name, p in section.get("points", {}).items()}
        files = {name: str(p["file"]) for name, p in section.get("points", {}).items()}
        observation = section.get("observation")
        return cls(
            case, points, files,
            None if observation is None else str(observation["file"]),
            None if observation is None else Case(c1, observation["phi"],
                                                  observation.get("theta", 0.0)),
        )

    def posture(self) -> dict[str, Any]:
        """The imaged posture as the 3D view names a posture: movement is measured from it."""
        return {"name": "as imaged", "phi": self.case.phi, "theta": self.case.theta}

    def view_query(self) -> dict[str, float]:
        """Where the 3D view opens, so that the movement from the image shows at once.

        The first tracked set's target posture at the imaged C1, else the imaged posture.
        """
        case = next(iter(self.points.values()), self.case)
        return {"C1": case.C1, "phi": case.phi, "theta": case.theta}

    def input_files(self) -> list[str]:
        """The points and observation files (inputs of the workflow)."""
        return [*self.point_files.values(), *([self.observation] if self.observation else [])]


@dataclass(frozen=True, slots=True)
class WorkflowConfig:
    """The whole configuration of the workflow, validated and parsed.

    Attributes:
        mesh: the geometry and its meshing.
        solver: the FE settings of the solve jobs.
        solve_fe: the ``fe`` section as the solve jobs receive it: a ``chest`` contact
            obstacle written out from ``mesh.geometry`` (the jobs need no mesh section);
            without contact, ``fe`` itself.
        cases: the sweep, sorted.
        clinical: the clinical cases, in the config's order.
        fe_study: the FE study.
        surrogate: the surrogate settings.
        surrogate_study: the surrogate's study.
        imaged: the mesh as an image of the loaded breast, or None (stress-free).
        sections: the validated mapping (defaults filled, keys sorted), the source of the
            rules' params; read it through :meth:`section`.
    """

    mesh: MeshConfig
    solver: SolverSettings
    solve_fe: dict[str, Any]
    cases: tuple[Case, ...]
    clinical: tuple[Case, ...]
    fe_study: FEStudyConfig
    surrogate: SurrogateConfig
    surrogate_study: SurrogateStudyConfig
    imaged: ImagedConfig | None
    sections: dict[str, Any]

    @classmethod
    def from_mapping(
        cls, config: Mapping[str, Any], schema_path: str | Path = SCHEMA_PATH
    ) -> WorkflowConfig:
        """Validate ``config`` against the schema and parse every section.

        Args:
            config: the configuration as read from ``config.yaml`` (not modified).
            schema_path: the JSON schema (YAML) that states the bounds and defaults.

        Raises:
            ConfigError: naming the offending key(s), before any object is used.
        """
        sections = validated(config, schema_path)
        with _section("mesh.geometry"):
            BreastGeometry.from_mapping(sections["mesh"]["geometry"])  # its errors named apart
        with _section("mesh", tuple(sections["mesh"])):
            mesh = MeshConfig.from_mapping(sections["mesh"])
        with _section("fe", tuple(sections["fe"])):
            solver = SolverSettings.from_config(sections)
            solve_fe = resolve_obstacle(sections["fe"], sections["mesh"])
        with _section("sweep"):
            cases = tuple(sweep_cases(sections["sweep"]))
        with _section("clinical"):
            clinical = tuple(clinical_cases(sections["clinical"]))
        with _section("dataset.split"):  # checked here, not after every solve at aggregation
            split = SplitFractions(**sections["dataset"].get("split", {}))
        with _section("sweep"):
            check_sweep_splits(cases, clinical, split)
        fe_study = FEStudyConfig.from_sections(sections)
        with _section("surrogate"):
            surrogate = SurrogateConfig.from_mapping(sections["surrogate"])
        surrogate_study = SurrogateStudyConfig.from_sections(
            sections["surrogate_study"], surrogate, cases)
        with _section("reference_state"):
            imaged = ImagedConfig.from_section(sections["reference_state"])
        return cls(mesh, solver, solve_fe, cases, clinical, fe_study, surrogate, surrogate_study,
                   imaged, sections)

    def section(self, *keys: str) -> Any:
        """A copy of the validated value at ``keys``, e.g. ``section("mesh", "fixed")``."""
        value: Any = self.sections
        for key in keys:
            value = value[key]
        return copy.deepcopy(value)

    def sections_of(self, *names: str) -> dict[str, Any]:
        """Copies of the top-level sections ``names``, in that order."""
        return {name: self.section(name) for name in names}

    @property
    def chains(self) -> bool:
        """Whether the sweep's cases of one direction are solved as one chain (``fem.chain``)."""
        return bool(self.sections["sweep"]["chains"])

    def surrogate_held_out(self, split: str) -> SurrogateConfig:
        """The surrogate settings of the model trained on ``split`` (a held-out split).

        Raises:
            KeyError: if the sweep cannot form that split (:attr:`held_out_splits`).
        """
        if split not in self.held_out_splits:
            raise KeyError(f"the sweep forms no {split!r} split (it has {self.held_out_splits})")
        return self.surrogate.replace(split=split)

    @property
    def held_out_splits(self) -> tuple[str, ...]:
        """The splits that hold out whole groups of the sweep and can be formed from it.

        ``by_case`` always; ``by_direction`` with at least three directions; ``by_c1`` with
        at least three C1 values besides the softest and the stiffest, which always train
        (:func:`fem.dataset.group_partition`).
        """
        phi = np.array([case.phi for case in self.cases], dtype=float)
        theta = np.array([case.theta for case in self.cases], dtype=float)
        directions = len(set(direction_keys(phi, theta))) if self.cases else 0
        c1_values = len({round(case.C1, 9) for case in self.cases})
        return tuple(
            split
            for split, enough in (
                ("by_case", True), ("by_direction", directions >= 3), ("by_c1", c1_values >= 5)
            )
            if enough
        )


def main(argv: list[str] | None = None) -> int:
    """``python -m studies.config FILE...``: check config files as a run would, before it starts.

    Prints one line per file (its number of cases, or what is wrong) and exits 2 if any is
    invalid. ``make reproduce`` runs it first: Snakemake reads a ``--configfile`` itself and
    reports a YAML syntax error without its line.
    """
    import argparse

    parser = argparse.ArgumentParser(prog="python -m studies.config", description=main.__doc__)
    parser.add_argument("files", nargs="+", type=Path, help="config files (YAML)")
    args = parser.parse_args(argv)
    status = 0
    for path in args.files:
        try:
            config = WorkflowConfig.from_mapping(read_config_file(path))
        except ConfigError as err:
            print(f"{path}: invalid configuration: {err}", file=sys.stderr)
            status = 2
        else:
            print(f"{path}: valid, {len(config.cases)} cases")
    return status


if __name__ == "__main__":
    sys.exit(main())

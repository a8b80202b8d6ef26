"""The surrogate study's config (``surrogate_study``): architectures, ablations, postures.

Parsed from the validated config by :meth:`SurrogateStudyConfig.from_sections`
(:meth:`run.config.WorkflowConfig.from_mapping` calls it).
"""

from __future__ import annotations

from collections.abc import Mapping
from dataclasses import dataclass
from typing import Any

from fem.sweep import Case, random_cases, sweep_cases
from studies.config_errors import ConfigError, config_section
from surrogate.config import SurrogateConfig, SurrogateConfigError, parse_architecture


@dataclass(frozen=True, slots=True)
class Ablation:
    """A named ablation (``surrogate_study.ablations``): the surrogate settings, some keys changed.

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
    with config_section("surrogate_study.off_grid"):
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
        repeats: trainings per architecture and per ablation.
        repeat_within: the architectures that train their repeats beyond the first: those
            whose first run's validation error is within this fraction of the best first
            run's (:func:`studies.surrogate_study.architecture.plan_repeats`); None, every
            architecture.
        ablations: the named ablations, in the config's (sorted) order.
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
    ablations: tuple[Ablation, ...]
    extrapolation: tuple[Case, ...]
    timing_repeats: int
    prediction_budget_ms: float | None
    postures: tuple[Posture, ...] = ()
    off_grid: tuple[Case, ...] = ()
    refit: bool = True
    repeat_within: float | None = None

    @classmethod
    def from_sections(
        cls, study: Mapping[str, Any], surrogate: SurrogateConfig, sweep: tuple[Case, ...]
    ) -> SurrogateStudyConfig:
        """Build from the ``surrogate_study`` section, the surrogate settings and the sweep."""
        with config_section("surrogate_study.architectures"):
            parsed = [parse_architecture(a) for a in study["architectures"]]
            if len(set(parsed)) != len(parsed):
                raise ConfigError("surrogate_study.architectures lists one twice")
        ablations = []
        for name, overrides in study["ablations"].items():
            with config_section(f"surrogate_study.ablations.{name}"):
                try:
                    settings = SurrogateConfig.from_mapping({**surrogate.as_dict(), **overrides})
                except SurrogateConfigError as err:  # named as the ablation's key, not surrogate's
                    text = str(err).replace("surrogate.", f"surrogate_study.ablations.{name}.", 1)
                    raise ConfigError(text) from None
            ablations.append(Ablation(name, dict(overrides), settings))
        extra: set[Case] = set()
        for i, block in enumerate(study["extrapolation"]):
            with config_section(f"surrogate_study.extrapolation.{i}"):
                extra.update(sweep_cases(block))
        return cls(
            architectures=tuple(f"{layers}x{width}" for layers, width in parsed),
            repeats=study["repeats"],
            ablations=tuple(ablations),
            extrapolation=tuple(sorted(extra - set(sweep))),
            timing_repeats=study["timing_repeats"],
            prediction_budget_ms=study["prediction_budget_ms"],
            postures=postures_of(study.get("postures") or {}, sweep),
            off_grid=off_grid_cases(study.get("off_grid") or {}, sweep),
            refit=bool(study.get("refit", True)),
            repeat_within=study.get("repeat_within"),
        )

    def ablation(self, name: str) -> Ablation:
        """The ablation called ``name``."""
        for ablation in self.ablations:
            if ablation.name == name:
                return ablation
        raise KeyError(f"surrogate_study.ablations has no {name!r}")

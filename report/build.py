"""The workflow's report: one self-contained HTML page with its PNG figures beside it.

The page answers the user's request ("both speed and accuracy count: chart one against
the other, test stability where methods fail, and model no more than a scene needs")
and sets our results beside the paper's. Every number on it is read from the files the
workflow wrote, through their typed result objects (:mod:`report.context`), or from
:mod:`studies.paper` (the paper's). A result file that is absent leaves its part of the
page as a note; a file whose content does not match its type is an error.

:func:`build_report` is the entry point: it loads the context, builds each section
(:mod:`report.sections`, one module per section) and renders the page from the Jinja2
template ``templates/page.html.j2``.
"""

from __future__ import annotations

import logging
import os
from collections.abc import Callable, Mapping, Sequence
from pathlib import Path
from typing import Any

import jinja2

from report.context import INPUT_NAMES, Context
from report.html import para
from report.sections.corpus import corpus_section
from report.sections.extrapolation import extrapolation_section
from report.sections.fe_speed_accuracy import fe_speed_accuracy_section
from report.sections.generalisation import generalisation_section
from report.sections.mesh import mesh_section
from report.sections.paper import paper_section
from report.sections.reference import reference_section
from report.sections.run_time import run_time_section
from report.sections.scene_needs import scene_needs_section
from report.sections.skin import skin_section
from report.sections.stability import stability_section
from report.sections.surrogate_speed_accuracy import surrogate_speed_accuracy_section
from report.sections.sweep_cost import sweep_cost_section
from report.sections.sweep_design import sweep_design_section
from report.sections.training import training_section

log = logging.getLogger(__name__)

TITLE = "Breast biomechanics under gravity: FE and surrogate report"
INTRO = (
    "Both speed and accuracy count: this page charts one against the other for the "
    "finite-element (FE) model and the neural-network surrogate, tests where the solvers "
    "fail, says which model a given accuracy need calls for, and sets our results beside the "
    "paper's (Babarenda Gamage et al.). Every number comes from the workflow's result files."
)

#: The first report's sections (ids): what the first results a run writes show (the mesh, the
#: dataset, the selected model and Table 2, the run so far).
FIRST_SECTIONS = ("mesh", "surrogate-speed-accuracy", "paper", "sweep-design", "sweep-cost",
                  "run-time", "training")
FIRST_NOTE = (
    "This is the run's first report, written as soon as the dataset, the selected model and "
    "the 3D view exist. The studies that take longest (the FE study, the ablations, held-out "
    "models and postures, stability, the corpus of anatomies, the reference state) follow; "
    "the full report, {full}, has every section when the run ends."
)

#: (id, heading, builder) of every section, in page order.
SECTIONS: tuple[tuple[str, str, Callable[[Context], str]], ...] = (
    ("mesh", "Mesh", mesh_section),
    ("fe-speed-accuracy", "FE speed against accuracy", fe_speed_accuracy_section),
    ("surrogate-speed-accuracy", "Surrogate speed against accuracy",
     surrogate_speed_accuracy_section),
    ("generalisation", "The surrogate between its cases and in every posture",
     generalisation_section),
    ("extrapolation", "The surrogate outside its training data", extrapolation_section),
    ("scene-needs", "Model no more than a scene needs", scene_needs_section),
    ("stability", "Stability", stability_section),
    ("corpus", "A corpus of anatomies", corpus_section),
    ("skin", "What the skin changes", skin_section),
    ("reference", "From the imaged shape to the reference state", reference_section),
    ("paper", "The paper side by side", paper_section),
    ("sweep-design", "How the sweep chose its cases", sweep_design_section),
    ("sweep-cost", "Sweep cost", sweep_cost_section),
    ("run-time", "The time of this run", run_time_section),
    ("training", "Surrogate training", training_section),
)


def render_page(
    sections: Sequence[Mapping[str, str]], viewer: str | None = None, intro: str = INTRO
) -> str:
    """The page's HTML from the template; each section is ``{id, title, html}``.

    ``viewer`` is the interactive view's address relative to the page, linked from the top.
    """
    env = jinja2.Environment(
        loader=jinja2.PackageLoader("report", "templates"),
        autoescape=jinja2.select_autoescape(["html", "j2"]),
        undefined=jinja2.StrictUndefined,
    )
    return env.get_template("page.html.j2").render(
        title=TITLE, intro=intro, sections=sections, viewer=viewer
    )


def build_report(
    inputs: Mapping[str, Any], html_path: str | Path, clinical: Sequence[Mapping[str, Any]],
    first: bool = False,
) -> Path:
    """Write the report page and its figures.

    Args:
        inputs: paths by the names of :data:`report.context.INPUT_NAMES` (the report rule's
            named inputs); a name that is absent leaves its part of the page as a note.
            ``clinical_fields`` is a list of the clinical error fields
            (``.../{by_sample,by_case}/<case>.xdmf`` with their ``.h5``).
        html_path: the page to write; the PNG figures are written beside it.
        clinical: the config's ``clinical`` entries (``C1``, ``phi``, ``theta``, ``label``).
        first: the run's first report: only :data:`FIRST_SECTIONS`, and the intro says that
            the full report (``../index.html`` from the page) follows.

    Returns:
        The page's path.

    Raises:
        studies.results.ResultFormatError: if a result file does not match its type (a key
            missing, renamed or of the wrong type).
    """
    html_path = Path(html_path)
    out_dir = html_path.parent
    out_dir.mkdir(parents=True, exist_ok=True)
    unknown = sorted(set(inputs) - set(INPUT_NAMES))
    if unknown:
        log.warning("report inputs not used: %s", ", ".join(unknown))
    ctx = Context.load(inputs, out_dir, clinical)
    sections = []
    for section_id, title, builder in SECTIONS:
        if first and section_id not in FIRST_SECTIONS:
            continue
        try:
            content = builder(ctx)
        except (KeyError, TypeError, ValueError, IndexError, OSError) as err:
            # one section's unexpected input must not cost the whole page; the page says so
            log.exception("section %r could not be built", title)
            content = para(f"This section could not be built: {type(err).__name__}: {err}",
                           "error")
        sections.append({"id": section_id, "title": title, "html": content})
    viewer = inputs.get("viewer")
    if viewer:
        viewer = Path(os.path.relpath(Path(str(viewer)).resolve(), out_dir.resolve())).as_posix()
    intro = INTRO
    if first:
        intro += " " + FIRST_NOTE.format(full=(out_dir.parent / "index.html").as_posix())
    html_path.write_text(render_page(sections, viewer or None, intro))
    log.info("wrote %s with %d sections", html_path, len(sections))
    return html_path


__all__ = ["FIRST_SECTIONS", "SECTIONS", "build_report", "render_page"]

"""How fast the interactive view answers: one update measured in the page, in headless Chromium.

    .venv/bin/python -m benchmarks.viewer_benchmark results/viewer/index.html [--updates 200]

One update is what a user's drag costs: the surrogate's prediction at the surface vertices in
the page's JavaScript, the colours, and one frame drawn and finished (``gl.finish``). The page
times it (``window.viewer.benchmark``); this prints the median, 95th percentile and largest of
``--updates`` updates after a warm-up, the page's size (three.js included) and the machine.
"""

from __future__ import annotations

import argparse
import sys
from dataclasses import dataclass
from pathlib import Path

import numpy as np

from studies.results import Result
from studies.surrogate_study.browser import open_page
from studies.timing_hygiene import MachineState, machine_state

FRAME_BUDGET_MS = 33.0
"""One update within a frame at 30 frames a second."""
PAGE_BUDGET_MB = 5.0


@dataclass(frozen=True, slots=True)
class ViewerBenchmark(Result):
    """An update's time in the page, and the page's size (``--json``)."""

    page: str
    page_mb: float
    points: int
    surface_vertices: int
    updates: int
    median_ms: float
    p95_ms: float
    max_ms: float
    machine: MachineState


def run_benchmark(page_path: str | Path, updates: int = 200, warmup: int = 20) -> ViewerBenchmark:
    """Time ``updates`` updates of the view in headless Chromium (after ``warmup`` more)."""
    with open_page(page_path, ready="window.viewer && window.viewer.ready") as (page, errors, _):
        page.evaluate(f"window.viewer.benchmark({warmup})")
        times = np.asarray(page.evaluate(f"window.viewer.benchmark({updates})"))
        counts = page.evaluate("[window.viewer.nPoints, window.viewer.nSurface]")
        if errors:
            raise RuntimeError(f"the page reported errors: {errors}")
    return ViewerBenchmark(
        page=str(page_path),
        page_mb=Path(page_path).stat().st_size / 1e6,
        points=int(counts[0]),
        surface_vertices=int(counts[1]),
        updates=updates,
        median_ms=float(np.median(times)),
        p95_ms=float(np.percentile(times, 95)),
        max_ms=float(times.max()),
        machine=machine_state(),
    )


def format_benchmark(result: ViewerBenchmark) -> str:
    """The figures as lines of text, with the budgets beside them."""
    return "\n".join([
        f"viewer {result.page}: {result.points} material points, "
        f"{result.surface_vertices} surface vertices drawn",
        f"page {result.page_mb:.2f} MB with three.js (budget {PAGE_BUDGET_MB:g} MB)",
        f"one update (prediction + colours + frame), {result.updates} updates: median "
        f"{result.median_ms:.2f} ms, 95th percentile {result.p95_ms:.2f} ms, largest "
        f"{result.max_ms:.2f} ms (budget {FRAME_BUDGET_MS:g} ms)",
        f"machine: {result.machine.cpu}, {result.machine.cores} cores, load "
        f"{result.machine.load_average_1_5_15min[0]:.2f}",
    ])


def main(argv: list[str] | None = None) -> int:
    """Print the benchmark (``--json FILE`` writes it too)."""
    parser = argparse.ArgumentParser(prog="python -m benchmarks.viewer_benchmark",
                                     description=__doc__.split("\n\n")[0])
    parser.add_argument("page", type=Path, help="the viewer's index.html")
    parser.add_argument("--updates", type=int, default=200)
    parser.add_argument("--json", type=Path, help="also write the figures here")
    args = parser.parse_args(argv)
    result = run_benchmark(args.page, args.updates)
    print(format_benchmark(result))
    if args.json:
        result.write(args.json)
    return 0


if __name__ == "__main__":
    sys.exit(main())

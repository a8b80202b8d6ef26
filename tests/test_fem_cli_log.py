"""``python -m fem.cli`` says what the solve does as it does it (issue 70).

A solve of an image-resolution mesh ran 25 minutes without a line: FFCx, imported with dolfinx,
had configured the root logger first, so the command's own ``basicConfig`` did nothing, and the
load steps were logged at DEBUG. Each Newton iteration and each load step is a line on the
console, in the order they happen, then the case's outcome.
"""

from __future__ import annotations

import json
import re
import subprocess
import sys
from pathlib import Path

import pytest

from tests.conftest import REPO

pytestmark = pytest.mark.solve


def test_the_command_line_logs_each_newton_iteration_and_load_step(
    coarse_mesh: Path, tmp_path: Path
) -> None:
    run = subprocess.run(
        [sys.executable, "-m", "fem.cli", str(coarse_mesh), "--c1", "1", "--phi", "90",
         "--out", str(tmp_path / "case")],
        cwd=REPO, capture_output=True, text=True, timeout=600)
    assert run.returncode == 0, run.stderr[-2000:]
    summary = json.loads(run.stdout)
    assert summary["status"] == "converged"
    lines = run.stderr.splitlines()

    def where(pattern: str) -> list[int]:
        return [i for i, line in enumerate(lines) if re.search(pattern, line)]

    iterations = where(r"INFO fem\.snes_system: Newton iteration \d+: residual \d\.\d{3}e[-+]\d+$")
    steps = where(r"INFO fem\.loading: load step to λ=\d\.\d{4} \(step \d\.\d{4}\): \w+ in "
                  r"\d+ Newton iterations$")
    outcome = where(r"INFO fem\.case: c1=1\.00_phi=90\.0_theta=0\.0: converged in \d+ steps")
    assert len(steps) == summary["load_steps"] >= 1, run.stderr[-2000:]
    assert len(iterations) >= 2 * len(steps)  # each step: its first residual, then Newton's
    assert len(outcome) == 1
    # as they happen: each step's line follows its iterations, the outcome follows them all
    assert iterations[0] < steps[0] and steps[-1] < outcome[0]
    assert re.search(r"λ=1\.0000", lines[steps[-1]])

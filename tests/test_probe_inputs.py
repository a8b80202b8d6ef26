"""The probe of bad configs and bad files (tests/probe_inputs.py) passes every probe."""

from __future__ import annotations

import re
import subprocess
import sys

import pytest

from tests.conftest import REPO

pytestmark = pytest.mark.workflow


def test_every_bad_config_and_file_is_refused_by_name() -> None:
    run = subprocess.run(
        [sys.executable, str(REPO / "tests" / "probe_inputs.py"), "-j", "2"],
        capture_output=True, text=True, timeout=900, cwd=REPO,
    )
    failed = [line for line in run.stdout.splitlines() if not line.startswith("PASS")]
    assert run.returncode == 0, "\n".join(failed) + run.stderr[-3000:]
    assert re.search(r"^\d+ passed, 0 failed$", run.stdout, re.M)

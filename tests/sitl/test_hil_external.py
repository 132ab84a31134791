"""The interop tests pass when pointed, through connection strings, at a pair started outside
pytest. This test starts navig8-bridge and navig8-fc itself (`sitl_helpers.external_pair`: the FC's GCS link as
tcpin: on a free port, as a companion computer would serve it), then runs `pytest tests/sitl/test_hil_interop.py
--fc-gcs=tcp:... --fc-api=udpin:... --bridge=...` as a separate process: everything but the local-log check must
pass. The whole `make test-hil` set against such a pair: `python tests/sitl/hil_pair.py` (docs/hil.md)."""

from __future__ import annotations

import re
import subprocess
import sys
from pathlib import Path

from sitl_helpers import external_pair

ROOT = Path(__file__).resolve().parents[2]


def test_interop_suite_against_a_pair_started_outside_pytest(tmp_path: Path) -> None:
    with external_pair(tmp_path) as ext:
        inner = subprocess.run(
            [sys.executable, "-m", "pytest", "-q", "-p", "no:cacheprovider", "tests/sitl/test_hil_interop.py",
             f"--fc-gcs={ext['fc_gcs']}", f"--fc-api={ext['fc_api']}", f"--bridge={ext['bridge']}"],
            cwd=ROOT, capture_output=True, text=True, timeout=240)
    tail = inner.stdout[-3000:]
    assert inner.returncode == 0, tail
    assert re.search(r"\b6 passed, 1 skipped\b", tail), tail
    assert "its log is not here" in tail, tail

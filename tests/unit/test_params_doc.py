"""docs/params.md is generated from the definitions; a stale page fails here (fix: `make docs`)."""

from pathlib import Path

from navig8_tools.params_doc import render

ROOT = Path(__file__).resolve().parents[2]


def test_params_doc_is_current() -> None:
    assert (ROOT / "docs" / "params.md").read_text() == render(), "docs/params.md is stale: run `make docs`"

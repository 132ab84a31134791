"""YAML text parsed with libyaml's safe loader where PyYAML has it, else PyYAML's pure-Python one: the same documents
(the constructors are PyYAML's own) for a tenth of the CPU. The parameter definitions (50 KB) took ~0.2 s in pure
Python, paid at every FC start and by every registry a test builds; the world's and the plant's files at every bridge
start and every flight (docs/results.md, "Test suite time"). Parsing only: the caller reads the text.
"""

from __future__ import annotations

from typing import Any

import yaml

SAFE_LOADER = getattr(yaml, "CSafeLoader", yaml.SafeLoader)


def safe_load(text: str) -> Any:
    """yaml.safe_load(text), on libyaml when available."""
    return yaml.load(text, Loader=SAFE_LOADER)  # noqa: S506 - a safe loader (CSafeLoader or SafeLoader)

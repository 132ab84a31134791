"""ParamStore: atomic JSON persistence of parameter values per instance."""

from __future__ import annotations

import json
import os
from pathlib import Path

import pytest

from navig8_fc.params.store import FORMAT_NAME, FORMAT_VERSION, ParamStore, default_state_path, json_depth


def test_round_trip_keeps_ints_and_floats(tmp_path: Path) -> None:
    store = ParamStore(tmp_path / "p.json")
    store.save({"INDI_K_MIN": 0.6, "INDI_RATE_HZ": 200})
    values, reason = store.load()
    assert reason is None
    assert values == {"INDI_K_MIN": 0.6, "INDI_RATE_HZ": 200}
    assert isinstance(values["INDI_RATE_HZ"], int)
    doc = json.loads((tmp_path / "p.json").read_text())
    assert doc["format"] == FORMAT_NAME and doc["version"] == FORMAT_VERSION


def test_missing_file_gives_empty_and_reason(tmp_path: Path) -> None:
    values, reason = ParamStore(tmp_path / "nope.json").load()
    assert values == {}
    assert reason and "no parameter file" in reason


@pytest.mark.parametrize(
    "content",
    ["{not json", '{"format": "other", "version": 1, "params": {}}', '{"format": "navig8-fc-params", "version": 99}',
     "[1, 2]", '{"format": "navig8-fc-params", "version": 1, "params": [1]}', "\xff\xfe",
     '{"format": "navig8-fc-params", "version": 1, "params": {"OL_POS_K": 1.0, "OL_POS_K": 9.0}}'],  # a name twice
)
def test_corrupt_file_gives_empty_and_reason(tmp_path: Path, content: str) -> None:
    p = tmp_path / "p.json"
    p.write_text(content, encoding="latin-1")
    values, reason = ParamStore(p).load()
    assert values == {}
    assert reason
    assert p.read_text(encoding="latin-1") == content  # left alone for a person to inspect


def test_a_file_with_a_bad_entry_is_not_used_at_all(tmp_path: Path) -> None:
    p = tmp_path / "p.json"
    p.write_text(json.dumps({"format": FORMAT_NAME, "version": 1,
                             "params": {"A_B": 1.5, "C_D": "x", "E_F": True, "G_H": None}}))
    values, reason = ParamStore(p).load()
    assert values == {}  # used whole or not at all
    assert reason and "C_D" in reason and "E_F" in reason and "G_H" in reason and "A_B" not in reason


_GOOD = json.dumps({"format": FORMAT_NAME, "version": 1, "params": {"OL_POS_K": 2.0}})
CORRUPT_VARIANTS = {
    "garbage": "\x00\x17garbage\x9c",
    "truncated": _GOOD[: len(_GOOD) // 2],
    "nan_literal": _GOOD.replace("2.0", "NaN"),
    "infinity_literal": _GOOD.replace("2.0", "-Infinity"),
    "deep_brackets": "[" * 200_000,
    "deep_in_budget": "[" * 30_000 + "]" * 30_000,
    "oversize": _GOOD + " " * 70_000,
}


@pytest.mark.parametrize("variant", sorted(CORRUPT_VARIANTS))
def test_unusable_files_give_a_reason_and_can_be_set_aside(tmp_path: Path, variant: str) -> None:
    p = tmp_path / "p.json"
    p.write_text(CORRUPT_VARIANTS[variant], encoding="latin-1")
    store = ParamStore(p)
    values, reason = store.load()
    assert values == {} and reason and str(p) in reason
    aside = store.set_aside()
    assert aside is not None and aside.name == "p.json.rejected-1" and not p.exists()
    assert aside.read_text(encoding="latin-1") == CORRUPT_VARIANTS[variant]  # kept, byte for byte


def test_a_directory_in_place_of_the_file_is_reported(tmp_path: Path) -> None:
    p = tmp_path / "p.json"
    p.mkdir()
    values, reason = ParamStore(p).load()
    assert values == {} and reason and "not a regular file" in reason


def test_json_depth_ignores_brackets_in_strings() -> None:
    assert json_depth('{"a": [1, {"b": "[[[{{{"}]}') == 3
    assert json_depth("[" * 1000) == 1000


def test_save_is_atomic_and_leaves_no_temp_files(tmp_path: Path) -> None:
    p = tmp_path / "sub" / "p.json"
    store = ParamStore(p)
    store.save({"A_B": 1.0})
    store.save({"A_B": 2.0})
    assert store.load().values == {"A_B": 2.0}
    assert sorted(os.listdir(p.parent)) == ["p.json"]


def test_failed_save_keeps_old_file(tmp_path: Path) -> None:
    p = tmp_path / "p.json"
    store = ParamStore(p)
    store.save({"A_B": 1.0})
    with pytest.raises(ValueError):
        store.save({"A_B": float("nan")})
    assert store.load().values == {"A_B": 1.0}
    assert sorted(os.listdir(tmp_path)) == ["p.json"]


def test_default_state_path_per_instance(tmp_path: Path) -> None:
    a, b = default_state_path(tmp_path, 0), default_state_path(tmp_path, 1)
    assert a != b and a.parent == tmp_path and b.name.endswith(".json")
    with pytest.raises(ValueError):
        default_state_path(tmp_path, -1)

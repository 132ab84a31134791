"""navig8-sitl --set / --params: parameters stored for the instance before navig8-fc starts; a refused one changes
nothing. The preset files of params/presets (.parm, MAVProxy's `param load` format) load whole."""

from __future__ import annotations

from pathlib import Path

import pytest

from navig8_fc.params.registry import ParamRegistry
from navig8_fc.params.store import ParamStore, default_state_path, parse_parm_text, read_overrides, read_parm_file
from navig8_fc.shell.sitl import main

REPO = Path(__file__).resolve().parents[2]


def test_refused_value_stops_before_anything_starts_and_stores_nothing(tmp_path: Path, capsys) -> None:
    assert main(["--set", "CKF_MODE=7", "--state-dir", str(tmp_path), "--instance", "3"]) == 2
    assert "CKF_MODE" in capsys.readouterr().err
    assert not default_state_path(tmp_path, 3).exists()
    assert main(["--set", "NO_SUCH_PARAM=1", "--state-dir", str(tmp_path)]) == 2
    bad = tmp_path / "bad.parm"
    bad.write_text("INDI_ALLOC 1\nCKF_MODE 7\n")
    assert main(["--params", str(bad), "--state-dir", str(tmp_path / "s")]) == 2
    assert "bad.parm" in capsys.readouterr().err
    assert not (tmp_path / "s").exists()


def test_accepted_values_merge_into_the_instance_file(tmp_path: Path) -> None:
    from navig8_fc.shell.sitl import store_params

    assert store_params(str(tmp_path), 4, ["CKF_MODE=1"]) is None
    assert store_params(str(tmp_path), 4, ["INDI_LAMBDA_MIN=0.25"]) is None  # a second --set keeps the first
    values = ParamStore(default_state_path(tmp_path, 4)).load().values
    assert values["CKF_MODE"] == 1 and values["INDI_LAMBDA_MIN"] == 0.25  # 0.25: exact in REAL32


def test_params_file_then_set_and_defaults_start_clean(tmp_path: Path) -> None:
    from navig8_fc.shell.sitl import store_params

    f = tmp_path / "p.parm"
    f.write_text("# a comment\nINDI_LAMBDA_MIN 0.25\nCKF_MODE,1  # ArduPilot's comma form\n\n")
    st = tmp_path / "st"
    assert store_params(str(st), 0, ["OL_POS_K=1.5"]) is None
    assert store_params(str(st), 0, ["CKF_MODE=2"], [str(f)]) is None  # --set wins over the file
    values = ParamStore(default_state_path(st, 0)).load().values
    assert values["INDI_LAMBDA_MIN"] == 0.25 and values["CKF_MODE"] == 2 and values["OL_POS_K"] == 1.5
    # --defaults with --params: the defaults plus the file, whatever was stored before
    assert store_params(str(st), 0, [], [str(f)], from_defaults=True) is None
    values = ParamStore(default_state_path(st, 0)).load().values
    assert values["OL_POS_K"] == ParamRegistry.from_defaults()["OL_POS_K"] and values["CKF_MODE"] == 1


@pytest.mark.parametrize("text,where", [("INDI_ALLOC\n", ":1:"), ("A 1\nB x\n", ":2: B"), ("A nan\n", "finite"),
                                        ("A 1\nA 2\n", "twice"), ("A 1 2\n", ":1:")])
def test_parm_parser_names_the_bad_line(text: str, where: str) -> None:
    with pytest.raises(ValueError, match=where):
        parse_parm_text(text, "f.parm")


@pytest.mark.parametrize("preset", sorted((REPO / "params" / "presets").glob("*.parm")), ids=lambda p: p.stem)
def test_every_preset_loads_whole(preset: Path) -> None:
    values = read_parm_file(preset)
    reg = ParamRegistry.from_defaults()
    assert values and all(reg.set(k, v).accepted for k, v in values.items())
    assert all(reg[k] == pytest.approx(v, rel=1e-6) for k, v in values.items())  # REAL32 storage


def test_presets_exist() -> None:
    assert {p.stem for p in (REPO / "params" / "presets").glob("*.parm")} >= {"paper"}


def test_read_overrides_takes_files_in_order_then_set_items_and_names_the_culprit(tmp_path: Path) -> None:
    a, b = tmp_path / "a.parm", tmp_path / "b.parm"
    a.write_text("X 1\nY 2\n")
    b.write_text("Y 3\n")
    assert read_overrides([a, b], ["X=5", " Z = 0.5"]) == {"X": 5.0, "Y": 3.0, "Z": 0.5}
    with pytest.raises(ValueError, match="--set expects NAME=VALUE"):
        read_overrides([], ["X"])
    with pytest.raises(ValueError, match="--set expects NAME=VALUE"):
        read_overrides([], ["X=abc"])
    with pytest.raises(ValueError, match="--params .*missing.parm"):
        read_overrides([tmp_path / "missing.parm"])

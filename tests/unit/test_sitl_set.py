"""navig8-sitl --set: a parameter stored for the instance before navig8-fc starts; a refused one changes nothing."""

from __future__ import annotations

from pathlib import Path

from navig8_fc.params.store import ParamStore, default_state_path
from navig8_fc.shell.sitl import main


def test_refused_value_stops_before_anything_starts_and_stores_nothing(tmp_path: Path, capsys) -> None:
    assert main(["--set", "CKF_MODE=7", "--state-dir", str(tmp_path), "--instance", "3"]) == 2
    assert "CKF_MODE" in capsys.readouterr().err
    assert not default_state_path(tmp_path, 3).exists()
    assert main(["--set", "NO_SUCH_PARAM=1", "--state-dir", str(tmp_path)]) == 2
    assert main(["--set", "CKF_MODE=1", "--defaults", "--state-dir", str(tmp_path)]) == 2
    assert not list(tmp_path.iterdir())


def test_accepted_values_merge_into_the_instance_file(tmp_path: Path) -> None:
    from navig8_fc.shell.sitl import _store_params

    assert _store_params(str(tmp_path), 4, ["CKF_MODE=1"]) is None
    assert _store_params(str(tmp_path), 4, ["INDI_LAMBDA_MIN=0.25"]) is None  # a second --set keeps the first
    values = ParamStore(default_state_path(tmp_path, 4)).load().values
    assert values["CKF_MODE"] == 1 and values["INDI_LAMBDA_MIN"] == 0.25  # 0.25: exact in REAL32

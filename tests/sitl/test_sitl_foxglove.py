"""Foxglove from the flight controller (docs/foxglove.md): the SITL log's foxglove.* channels validate against
Foxglove's published JSON schemas and its transforms match the arm kinematics (1e-6 m); `navig8-sitl --foxglove`
streams the same channels live to a WebSocket client speaking Foxglove's protocol."""

from __future__ import annotations

import sys
from pathlib import Path

from sitl_helpers import sitl

sys.path.insert(0, str(Path(__file__).resolve().parents[1] / "unit"))  # the oracles beside the unit tests

from foxglove_oracle import check_log  # noqa: E402

from navig8_fc.core.vehicle import VehicleConfig  # noqa: E402


def test_sitl_log_foxglove_channels_validate_and_transforms_match_kinematics(tmp_path: Path) -> None:
    with sitl(tmp_path, scenario="paper", speed=0.0, fc_args=["--until-done"],
              bridge_args=["--until-done", "--duration", "2"]) as run:
        assert run.fc.wait(timeout=120) == 0
    counts = check_log(run.log, VehicleConfig.load(), {"/foxglove/tf": 90, "/foxglove/scene": 18,
                                                        "/foxglove/path": 4, "/foxglove/mission": 4})
    assert counts["/foxglove/tf"] <= 102  # 50 Hz of sim time, not every 2 ms step

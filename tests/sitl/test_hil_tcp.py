"""The FC in real-time mode and the bridge free-running over TCP, as PX4's simulator interface
(the simulator listens, here on a free port instead of 4560; the FC connects): takeoff, hover, land."""

from __future__ import annotations

from pathlib import Path

import pytest
from sitl_helpers import fly_realtime

pytestmark = pytest.mark.realtime  # on the wall clock: run alone, after the parallel SITL lane (make test)

def test_realtime_fc_flies_over_tcp(tmp_path: Path) -> None:
    fly_realtime(tmp_path, "tcp")

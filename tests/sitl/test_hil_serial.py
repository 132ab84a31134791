"""The FC in real-time mode and the bridge free-running over a serial line at 921600 baud:
takeoff, hover, land. The line is a pair of pseudo-terminals joined by navig8_tools.nullmodem, which delays each
direction by its transmission time at 921600 baud (8N1); a pty is not a UART (no bit errors, no FIFO gaps)."""

from __future__ import annotations

from pathlib import Path

import pytest
from sitl_helpers import fly_realtime

from navig8_tools.nullmodem import NullModem

pytestmark = pytest.mark.realtime  # on the wall clock: run alone, after the parallel SITL lane (make test)

# Over this line the actuator identification (ACT_ID) reads the link's delay (a bundle takes ~8 ms at 921600 baud)
# as a slower actuator, and in some runs its innovation then trips the actuator model's supervision, which flies the
# measured U0: the hover then sags and sways by up to 0.66 / 0.73 m (on UDP and TCP it holds 0.3 m). A known defect
# (docs/hil.md, "Not done yet"); the bound here is the fallback's, so the test still fails on a loss of control, a
# stuck takeoff or a line that drops out.
SERIAL_HOVER_TOL_M = 1.0


def test_realtime_fc_flies_over_a_921600_baud_serial_line(tmp_path: Path) -> None:
    with NullModem(921600) as line:
        fly_realtime(tmp_path, "serial", line.paths, SERIAL_HOVER_TOL_M, SERIAL_HOVER_TOL_M)
        wall_s = line.elapsed_s()
        # what crossed the line each way fits it (~92 kB/s at 921600 8N1): the bridge's budget held
        assert 0 < line.bytes[0] / wall_s < 92160 and 0 < line.bytes[1] / wall_s < 92160, (line.bytes, wall_s)

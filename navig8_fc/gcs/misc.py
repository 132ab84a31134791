"""Small GCS-facing services: TIMESYNC (the others have grown into their own modules).

MAVFTP (FILE_TRANSFER_PROTOCOL) is navig8_fc.gcs.ftp (read-only: the component metadata).

The mission protocol has its own module (navig8_fc.gcs.mission_protocol).

TIMESYNC: a request (tc1 == 0) is answered with tc1 = now_s in ns and ts1 echoed (TIMESYNC v2: addressed
to the requester when the dialect has the target fields). The shell chooses the clock: navig8-fc passes the
host's monotonic clock, the one time_boot_ms counts on (sim time stands still between lockstep steps).
"""

from __future__ import annotations

from typing import Any

from pymavlink.dialects.v20 import common as mavlink2

from navig8_fc.gcs.statustext import StatusTextEncoder

M = mavlink2


class MiscProtocols:
    """TIMESYNC for one component (module docstring)."""

    def __init__(
        self,
        mav: Any,
        sysid: int | None = None,
        compid: int | None = None,
        *,
        statustext: StatusTextEncoder | None = None,
    ) -> None:
        self._mav = mav
        self._sysid = int(mav.srcSystem if sysid is None else sysid)
        self._compid = int(mav.srcComponent if compid is None else compid)
        self._text = statustext or StatusTextEncoder(mav)

    def handle(self, msg: Any, now_s: float) -> list[Any]:
        kind = msg.get_type()
        if kind == "TIMESYNC":
            return self._timesync(msg, now_s)
        return []

    def _timesync(self, msg: Any, now_s: float) -> list[Any]:
        if int(msg.tc1) != 0:
            return []  # a response (possibly to someone else): nothing to answer
        target = (int(getattr(msg, "target_system", 0)), int(getattr(msg, "target_component", 0)))
        if target[0] not in (0, self._sysid) or target[1] not in (0, self._compid):
            return []
        reply = self._mav.timesync_encode(int(now_s * 1e9), int(msg.ts1))
        if "target_system" in reply.fieldnames:  # TIMESYNC v2 (newer common.xml): address the requester
            reply.target_system = msg.get_srcSystem()
            reply.target_component = msg.get_srcComponent()
        return [reply]



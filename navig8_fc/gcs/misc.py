"""Small GCS-facing services: an empty mission, TIMESYNC.

MAVFTP (FILE_TRANSFER_PROTOCOL) is navig8_fc.gcs.ftp (read-only: the component metadata).

Mission protocol (mavlink_notes §2.5; full missions come later):
- MISSION_REQUEST_LIST -> MISSION_COUNT(count 0, the request's mission_type): an empty mission, so QGC's
  connect sequence and MAVSDK's download finish at once.
- MISSION_COUNT(0) from a GCS (an upload of nothing, i.e. a clear) -> MISSION_ACK(ACCEPTED);
  MISSION_COUNT(n > 0) -> MISSION_ACK(MAV_MISSION_UNSUPPORTED) + STATUSTEXT: upload is not implemented yet,
  and UNSUPPORTED tells the user exactly that (MAVSDK reports Result::Unsupported) without pretending a
  storage limit (NO_SPACE) or a permission problem (DENIED).
- MISSION_CLEAR_ALL -> MISSION_ACK(ACCEPTED) (the mission is empty afterwards, trivially).
- MISSION_REQUEST_INT / MISSION_REQUEST for any seq -> MISSION_ACK(INVALID_SEQUENCE): there is no item.
All replies echo mission_type and are addressed to the requester.

TIMESYNC: a request (tc1 == 0) is answered with tc1 = now_s in ns and ts1 echoed (TIMESYNC v2: addressed
to the requester when the dialect has the target fields). The shell chooses the clock: in SITL our "now"
is sim time (mavlink_notes §2.8).
"""

from __future__ import annotations

from typing import Any

from pymavlink.dialects.v20 import common as mavlink2

from navig8_fc.gcs.params import is_for_us
from navig8_fc.gcs.statustext import StatusTextEncoder

M = mavlink2


class MiscProtocols:
    """The empty mission and TIMESYNC for one component (module docstring)."""

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
        if kind not in _HANDLED or not is_for_us(msg, self._sysid, self._compid):
            return []
        mission_type = int(getattr(msg, "mission_type", M.MAV_MISSION_TYPE_MISSION))
        src_sys, src_comp = msg.get_srcSystem(), msg.get_srcComponent()
        if kind == "MISSION_REQUEST_LIST":
            return [self._mav.mission_count_encode(src_sys, src_comp, 0, mission_type)]
        if kind == "MISSION_COUNT":
            if int(msg.count) == 0:
                return [self._mav.mission_ack_encode(src_sys, src_comp, M.MAV_MISSION_ACCEPTED, mission_type)]
            ack = self._mav.mission_ack_encode(src_sys, src_comp, M.MAV_MISSION_UNSUPPORTED, mission_type)
            return [ack, *self._text.warning("Mission upload not supported yet")]
        if kind == "MISSION_CLEAR_ALL":
            return [self._mav.mission_ack_encode(src_sys, src_comp, M.MAV_MISSION_ACCEPTED, mission_type)]
        # MISSION_REQUEST_INT / MISSION_REQUEST: there is no item to send.
        return [self._mav.mission_ack_encode(src_sys, src_comp, M.MAV_MISSION_INVALID_SEQUENCE, mission_type)]

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


_HANDLED = frozenset({
    "MISSION_REQUEST_LIST", "MISSION_COUNT", "MISSION_CLEAR_ALL",
    "MISSION_REQUEST_INT", "MISSION_REQUEST",
})  # fmt: skip

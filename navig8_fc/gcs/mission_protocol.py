"""MAVLink mission microservice of the vehicle (mission types MISSION, FENCE and RALLY): message in -> messages out.

The caller (navig8_fc.shell.gcs_service) routes: `handle(msg, now_s, source)` returns the replies for the
sender (STATUSTEXT among them is broadcast); `poll(now_s)` returns (source, message) pairs: re-requests for the
uploading ground station and, with source None, broadcasts (STATUSTEXT, MISSION_CURRENT, MISSION_ITEM_REACHED).
Times are the caller's clock (wall time: a ground station's retries run on wall time, not sim time).

Upload (the vehicle is the requester; devguide "Mission Protocol", PX4 mavlink_mission.cpp):
MISSION_COUNT(n) -> MISSION_REQUEST_INT(0) -> MISSION_ITEM_INT(0) -> ... -> MISSION_ACK(ACCEPTED).
- A request that goes unanswered is sent again every `retry_s` (250 ms, PX4's
  MAVLINK_MISSION_RETRY_TIMEOUT_DEFAULT); `timeout_s` (5 s, MAVLINK_MISSION_PROTOCOL_TIMEOUT_DEFAULT) without
  progress (the upload's start or an item accepted) ends the transfer with STATUSTEXT "Mission upload timed out".
- Items arrive into a new plan beside the one in force; the plan in force is replaced only when the last item
  has arrived and the whole plan is valid (`plan.check_item`/`check_plan`). A timeout, a cancel
  (MISSION_ACK OPERATION_CANCELLED from the uploader) or a refused item leaves the old plan in force.
- A refused item ends the upload with MISSION_ACK(the MAV_MISSION_RESULT naming the problem) + STATUSTEXT.
- The upload (the lock on the plans) belongs to its uploader: system id, component id and the source it sends
  from. An item whose seq is not the one requested is ignored (the request is repeated); items from anyone but
  the uploader are ignored. A MISSION_COUNT from the uploader during its upload restarts it (its earlier attempt
  timed out on its side) without extending the lock: only progress does, so MISSION_COUNT repeated forever holds
  nothing. From another sender: MISSION_ACK(DENIED) + STATUSTEXT while the upload progresses; once it has made
  no progress for `stale_s` (1 s: an uploader answers a request within milliseconds, PX4 asks again after
  250 ms) it no longer blocks anyone: another sender's MISSION_COUNT, clear or download ends it ("abandoned")
  and goes ahead.
- `item_check` (the operating volume, navig8_fc.mission.volume) may refuse a MISSION or RALLY item by its
  position: MISSION_ACK(INVALID_PARAM5_X / INVALID_PARAM7) + STATUSTEXT with the reason.
- Legacy MISSION_ITEM (float x/y) is accepted; a MISSION_ACK(UNSUPPORTED) from the uploader in answer to our
  MISSION_REQUEST_INT switches that upload to MISSION_REQUEST (PX4 does the same).
- The last item repeated after the final ACK (the ground station lost it) gets the same ACK again.
- MISSION_COUNT(0) clears that mission type (ACK ACCEPTED); n above the storage -> NO_SPACE; another type ->
  UNSUPPORTED.
Download: MISSION_REQUEST_LIST -> MISSION_COUNT(n) -> MISSION_REQUEST_INT(i) -> MISSION_ITEM_INT(i) (or
MISSION_REQUEST -> MISSION_ITEM) ... -> the ground station's MISSION_ACK. Items are sent exactly as stored, with
current = 1 on the plan's start item; a request for a seq >= n gets MISSION_ACK(INVALID_SEQUENCE).
MISSION_CLEAR_ALL(MISSION, FENCE, RALLY or ALL) -> MISSION_ACK(ACCEPTED) (ERROR while an upload runs).
MISSION_SET_CURRENT(seq) and MAV_CMD_DO_SET_MISSION_CURRENT (`set_current`) move the start/current item.
MISSION_CURRENT (seq, total = n or 65535 without a plan, mission_state, mission_mode) is broadcast at 1 Hz and at
once when it changes; MISSION_ITEM_REACHED(seq) at once and then once a second up to 10 more times (PX4): both
kept by navig8_fc/gcs/mission_status.py.

opaque_id: every plan has a CRC32 identity (`Plan.opaque_id`, 0 = no plan), sent in MISSION_ACK / MISSION_COUNT
`opaque_id` and MISSION_CURRENT `mission_id` / `fence_id` / `rally_points_id` whenever the dialect has those
extension fields (the FC's navig8 dialect adds them to pymavlink's common.xml, which lacks them;
navig8_fc.mavlink.dialect) and reported by `opaque_id(mission_type)` either way (docs/gcs.md).
"""

from __future__ import annotations

from collections.abc import Callable
from dataclasses import dataclass, field
from typing import Any

from navig8_fc.gcs.mission_status import MissionStatus
from navig8_fc.gcs.statustext import StatusTextEncoder
from navig8_fc.mission.plan import (
    MAX_ITEMS,
    MissionItem,
    MissionType,
    Plan,
    Problem,
    Progress,
    Result,
    check_item,
    check_plan,
    from_float_xy,
    to_float_xy,
)
from navig8_fc.mission.store import MissionStore

MAV_COMP_ID_MISSIONPLANNER = 190
STORED_TYPES = (MissionType.MISSION, MissionType.FENCE, MissionType.RALLY)


@dataclass
class _Upload:
    source: Any
    partner: tuple[int, int]
    mission_type: int
    count: int
    int_mode: bool
    last_request_s: float
    last_progress_s: float  # the start or the last item accepted (a restart by the uploader does not count)
    items: list[MissionItem] = field(default_factory=list)
    current: int = 0


@dataclass
class _Download:
    source: Any
    partner: tuple[int, int]
    mission_type: int
    last_rx_s: float


class MissionProtocol:
    """Mission microservice of one component (module docstring)."""

    def __init__(self, mav: Any, sysid: int, compid: int, store: MissionStore | None = None, *,
                 statustext: StatusTextEncoder | None = None, retry_s: float = 0.25, timeout_s: float = 5.0,
                 current_period_s: float = 1.0, stale_s: float = 1.0,
                 item_check: Callable[[MissionItem, int], Problem | None] | None = None) -> None:
        self._mav = mav
        self._sysid = int(sysid)
        self._compid = int(compid)
        self._store = store
        self._text = statustext or StatusTextEncoder(mav)
        self.retry_s = float(retry_s)
        self.timeout_s = float(timeout_s)
        self.stale_s = float(stale_s)
        self._item_check = item_check
        self._plans: dict[int, Plan] = {t: Plan(t) for t in STORED_TYPES}
        self._upload: _Upload | None = None
        self._download: _Download | None = None
        self._last_ack: tuple[tuple[int, int], int, int, int] | None = None  # partner, type, count, result
        self._outbox: list[tuple[Any, Any]] = []  # broadcasts decided in handle(), sent by poll()
        self.generation = 0  # changes whenever a plan or the current item changes (the executor watches it)
        self._status = MissionStatus(mav, self.plan, current_period_s)  # MISSION_CURRENT, MISSION_ITEM_REACHED

    # --- the plans ---------------------------------------------------------------------------------------
    def plan(self, mission_type: int = MissionType.MISSION) -> Plan:
        return self._plans.get(int(mission_type), Plan(int(mission_type)))

    def opaque_id(self, mission_type: int = MissionType.MISSION) -> int:
        return self.plan(mission_type).opaque_id

    @property
    def busy(self) -> bool:
        return self._upload is not None

    def load_stored(self) -> str | None:
        """Put the stored plans in force (startup); the reason when something in the file was not usable."""
        if self._store is None:
            return None
        loaded = self._store.load()
        for t, p in loaded.plans.items():
            self._plans[t] = p
        if loaded.plans:
            self.generation += 1
        return loaded.reason

    def set_current(self, seq: int, reset: bool = False) -> tuple[bool, str]:
        """MISSION_SET_CURRENT / DO_SET_MISSION_CURRENT: the item to fly next (reset: also forget what was
        reached, as p2 = 1 of DO_SET_MISSION_CURRENT asks); -1 keeps the current item."""
        p = self._plans[MissionType.MISSION]
        seq = p.current if seq == -1 and p.items else seq
        if not 0 <= seq < len(p.items):
            return False, f"Mission: no item {seq} (plan has {len(p.items)})"
        self._plans[MissionType.MISSION] = Plan(p.mission_type, p.items, seq)
        self.generation += 1
        self._status.set_current(seq, reset)
        self._save()
        return True, ""

    def report(self, progress: Progress) -> None:
        """The executor's progress (each service poll): MISSION_CURRENT follows it, a newly reached item is
        announced with MISSION_ITEM_REACHED."""
        self._outbox += [(None, m) for m in self._status.report(progress)]

    # --- inbound ------------------------------------------------------------------------------------------
    def handle(self, msg: Any, now_s: float, source: Any = None) -> list[Any]:
        kind = msg.get_type()
        if kind not in _HANDLED or not self._for_us(msg):
            return []
        partner = (int(msg.get_srcSystem()), int(msg.get_srcComponent()))
        mission_type = int(getattr(msg, "mission_type", MissionType.MISSION))
        abandoned = self._abandon_stale(partner, source, now_s)
        if abandoned:
            return abandoned + self.handle(msg, now_s, source)
        if kind == "MISSION_COUNT":
            return self._count(msg, now_s, source, partner, mission_type)
        if kind in ("MISSION_ITEM_INT", "MISSION_ITEM"):
            return self._item(msg, now_s, (partner, source), mission_type, kind == "MISSION_ITEM_INT")
        if kind == "MISSION_REQUEST_LIST":
            return self._request_list(now_s, source, partner, mission_type)
        if kind in ("MISSION_REQUEST_INT", "MISSION_REQUEST"):
            return self._request(msg, now_s, source, partner, mission_type, kind == "MISSION_REQUEST_INT")
        if kind == "MISSION_ACK":
            return self._ack_in(msg, partner, source, mission_type)
        if kind == "MISSION_CLEAR_ALL":
            return self._clear_all(partner, mission_type)
        ok, reason = self.set_current(int(msg.seq))  # MISSION_SET_CURRENT (no ACK in the protocol)
        return [] if ok else self._text.warning(reason)

    def poll(self, now_s: float) -> list[tuple[Any, Any]]:
        """Re-requests and timeouts of a running transfer, MISSION_CURRENT and MISSION_ITEM_REACHED (module
        docstring); source None = broadcast."""
        out, self._outbox = self._outbox, []
        up = self._upload
        if up is not None:
            if now_s - up.last_progress_s >= self.timeout_s:
                self._upload = None
                out += [(None, m) for m in self._text.warning(
                    f"Mission upload timed out at item {len(up.items)}/{up.count}: plan in force unchanged")]
            elif now_s - up.last_request_s >= self.retry_s:
                up.last_request_s = now_s
                out.append((up.source, self._request_msg(up)))
        dl = self._download
        if dl is not None and now_s - dl.last_rx_s >= self.timeout_s:
            self._download = None
        return out + [(None, m) for m in self._status.poll(now_s)]

    def mission_current(self) -> Any:
        return self._status.mission_current()

    # --- internals ----------------------------------------------------------------------------------------
    def _abandon_stale(self, partner: tuple[int, int], source: Any, now_s: float) -> list[Any]:
        """Another sender's message while the upload has made no progress for stale_s: the upload ends (module
        docstring); the STATUSTEXT saying so (empty: nothing abandoned)."""
        up = self._upload
        if up is None or (up.partner, up.source) == (partner, source) or now_s - up.last_progress_s < self.stale_s:
            return []
        self._upload = None
        return self._text.warning(f"Stale mission upload (sys {up.partner[0]}) abandoned")  # one STATUSTEXT

    def _for_us(self, msg: Any) -> bool:
        ts = getattr(msg, "target_system", 0)
        tc = getattr(msg, "target_component", 0)
        return ts in (0, self._sysid) and tc in (0, self._compid, MAV_COMP_ID_MISSIONPLANNER)

    def _ack(self, partner: tuple[int, int], result: int, mission_type: int, opaque_id: int = 0) -> Any:
        m = self._mav.mission_ack_encode(partner[0], partner[1], int(result), int(mission_type))
        if "opaque_id" in m.fieldnames:
            m.opaque_id = opaque_id
        return m

    def _refuse(self, partner: tuple[int, int], mission_type: int, problem: Problem) -> list[Any]:
        return [self._ack(partner, problem.result, mission_type), *self._text.warning(problem.reason)]

    def _request_msg(self, up: _Upload) -> Any:
        seq = len(up.items)
        if up.int_mode:
            return self._mav.mission_request_int_encode(up.partner[0], up.partner[1], seq, up.mission_type)
        return self._mav.mission_request_encode(up.partner[0], up.partner[1], seq, up.mission_type)

    def _count(self, msg: Any, now_s: float, source: Any, partner: tuple[int, int], mission_type: int) -> list[Any]:
        count = int(msg.count)
        up = self._upload
        if up is not None and (up.partner, up.source) != (partner, source):
            return self._refuse(partner, mission_type, Problem(
                Result.DENIED, f"Mission upload refused: system {up.partner[0]} is uploading"))
        started_s = now_s if up is None else up.last_progress_s  # a restart does not extend the lock
        self._upload = None  # the uploader's new MISSION_COUNT restarts its upload
        if mission_type not in STORED_TYPES:
            return self._refuse(partner, mission_type,
                                Problem(Result.UNSUPPORTED, f"Mission type {mission_type} not supported"))
        if count == 0:
            self._replace(Plan(mission_type))
            return [self._ack(partner, Result.ACCEPTED, mission_type)]
        limit = MAX_ITEMS[MissionType(mission_type)]
        if count > limit:
            return self._refuse(partner, mission_type,
                                Problem(Result.NO_SPACE, f"Mission upload: {count} items, at most {limit}"))
        self._download = None
        self._last_ack = None
        self._upload = _Upload(source, partner, mission_type, count, True, now_s, started_s)
        return [self._request_msg(self._upload)]

    def _item(self, msg: Any, now_s: float, sender: tuple[tuple[int, int], Any], mission_type: int, is_int: bool
              ) -> list[Any]:
        seq = int(msg.seq)
        partner = sender[0]
        up = self._upload
        if up is None:
            last = self._last_ack
            if last is not None and last[0] == partner and last[1] == mission_type and seq == last[2] - 1:
                return [self._ack(partner, last[3], mission_type, self.opaque_id(mission_type))]
            return []
        if sender != (up.partner, up.source):
            return []
        if mission_type != up.mission_type:
            self._upload = None
            return self._refuse(partner, mission_type, Problem(
                Result.ERROR, f"Mission upload: item of type {mission_type} during an upload of type "
                f"{up.mission_type}"))
        if seq != len(up.items):
            return []  # a duplicate or an item ahead of the request: the request is repeated (PX4)
        item, problem = _decode_item(msg, is_int)
        if problem is None:
            problem = check_item(item, up.mission_type, up.count)
        if problem is None and self._item_check is not None:
            problem = self._item_check(item, up.mission_type)
        if problem is not None:
            self._upload = None
            return self._refuse(partner, mission_type, Problem(problem.result, f"Item {seq}: {problem.reason}"))
        if not is_int:
            up.int_mode = False
        if int(msg.current) == 1:
            up.current = seq
        up.items.append(item)
        up.last_progress_s = now_s
        if len(up.items) < up.count:
            up.last_request_s = now_s
            return [self._request_msg(up)]
        self._upload = None
        items = tuple(up.items)
        problem = check_plan(items, up.mission_type)
        if problem is not None:
            return self._refuse(partner, mission_type, problem)
        warnings = self._replace(Plan(up.mission_type, items, up.current))
        self._last_ack = (partner, up.mission_type, up.count, Result.ACCEPTED)
        return [self._ack(partner, Result.ACCEPTED, mission_type, self.opaque_id(mission_type)), *warnings]

    def _replace(self, plan: Plan) -> list[Any]:
        """Put `plan` in force (atomically: one assignment), persist, announce."""
        self._plans[plan.mission_type] = plan
        self.generation += 1
        if plan.mission_type == MissionType.MISSION:
            self._status.new_plan(plan.current)
        return self._save()

    def _save(self) -> list[Any]:
        if self._store is None:
            return []
        try:
            self._store.save(self._plans)
        except (OSError, ValueError) as exc:
            return self._text.warning(f"Mission in force but not saved: {exc}")
        return []

    def _request_list(self, now_s: float, source: Any, partner: tuple[int, int], mission_type: int) -> list[Any]:
        if self._upload is not None:
            return self._refuse(partner, mission_type,
                                Problem(Result.ERROR, "Mission download refused: an upload is running"))
        count = len(self.plan(mission_type).items)
        self._download = _Download(source, partner, mission_type, now_s) if count else None
        m = self._mav.mission_count_encode(partner[0], partner[1], count, mission_type)
        if "opaque_id" in m.fieldnames:
            m.opaque_id = self.opaque_id(mission_type)
        return [m]

    def _request(self, msg: Any, now_s: float, source: Any, partner: tuple[int, int], mission_type: int,
                 is_int: bool) -> list[Any]:
        up = self._upload
        if up is not None:
            if partner == up.partner:
                return []  # a ground station asking for items while uploading: not a download
            return self._refuse(partner, mission_type, Problem(Result.ERROR, "Mission download: upload running"))
        p = self.plan(mission_type)
        seq = int(msg.seq)
        if not 0 <= seq < len(p.items):
            return [self._ack(partner, Result.INVALID_SEQUENCE, mission_type)]
        self._download = _Download(source, partner, mission_type, now_s)
        it = p.items[seq]
        current = int(seq == p.current) if mission_type == MissionType.MISSION else 0
        if is_int:
            return [self._mav.mission_item_int_encode(
                partner[0], partner[1], seq, it.frame, it.command, current, it.autocontinue, it.param1, it.param2,
                it.param3, it.param4, it.x, it.y, it.z, mission_type)]
        x, y = to_float_xy(it.frame, it.x, it.y)
        return [self._mav.mission_item_encode(
            partner[0], partner[1], seq, it.frame, it.command, current, it.autocontinue, it.param1, it.param2,
            it.param3, it.param4, x, y, it.z, mission_type)]

    def _ack_in(self, msg: Any, partner: tuple[int, int], source: Any, mission_type: int) -> list[Any]:
        up = self._upload
        if up is not None and (partner, source) == (up.partner, up.source):
            if int(msg.type) == Result.UNSUPPORTED and up.int_mode:
                up.int_mode = False  # the uploader cannot send MISSION_ITEM_INT: ask with MISSION_REQUEST
                return [self._request_msg(up)]
            self._upload = None
            return self._text.info(f"Mission upload cancelled by the ground station ({int(msg.type)})")
        if self._download is not None and partner == self._download.partner:
            self._download = None
        return []

    def _clear_all(self, partner: tuple[int, int], mission_type: int) -> list[Any]:
        if self._upload is not None:
            return self._refuse(partner, mission_type, Problem(Result.ERROR, "Mission clear refused: upload running"))
        types = STORED_TYPES if mission_type == MissionType.ALL else (mission_type,)
        warnings: list[Any] = []
        for t in types:
            if t in STORED_TYPES:
                warnings = self._replace(Plan(t))
        return [self._ack(partner, Result.ACCEPTED, mission_type), *warnings]


def _decode_item(msg: Any, is_int: bool) -> tuple[MissionItem, Problem | None]:
    frame = int(msg.frame)
    if is_int:
        x, y = int(msg.x), int(msg.y)
    else:
        xy = from_float_xy(frame, float(msg.x), float(msg.y))
        if xy is None:
            empty = MissionItem(frame, int(msg.command), 1, 0.0, 0.0, 0.0, 0.0, 0, 0, 0.0)
            return empty, Problem(Result.INVALID_PARAM5_X, "x/y must be numbers within range")
        x, y = xy
    item = MissionItem(frame, int(msg.command), int(msg.autocontinue), float(msg.param1), float(msg.param2),
                       float(msg.param3), float(msg.param4), x, y, float(msg.z))
    return item, None


_HANDLED = frozenset({
    "MISSION_COUNT", "MISSION_ITEM_INT", "MISSION_ITEM", "MISSION_REQUEST_LIST", "MISSION_REQUEST_INT",
    "MISSION_REQUEST", "MISSION_ACK", "MISSION_CLEAR_ALL", "MISSION_SET_CURRENT",
})  # fmt: skip

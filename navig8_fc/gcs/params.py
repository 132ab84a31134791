"""MAVLink parameter protocol over the parameter registry (message in -> messages out; the caller sends).

PARAM_REQUEST_LIST starts a paced download: `poll(now_s)` then emits PARAM_VALUE for every index exactly
once, in index order, at most `burst` per call and `rate_per_s` on average (a token bucket on the caller's
clock: wall time, so pacing does not depend on the simulation speed). A new PARAM_REQUEST_LIST restarts the
download from index 0 (clients retry the whole list when they time out, QGC up to 4 times). Downloads are
kept per requester (`handle(..., source=...)`, an opaque key such as (link, address)): `poll_routed` says
whom each PARAM_VALUE of a download is for, so a list requested on one link is not streamed to another;
two requesters are served one after the other, each list restarting only on its own requester's request.
PARAM_REQUEST_READ answers by index (param_index >= 0) or by name (param_index == -1); an unknown name or
index gets no PARAM_VALUE (there is nothing true to put in it) but a STATUSTEXT, as the spec asks.
PARAM_SET is validated by the registry (range, NaN/Inf, cross rules, stability floor) and always answered
with PARAM_VALUE carrying the value now in force: the new one, or the old one plus a STATUSTEXT(WARNING)
with the reason when refused. An unknown name cannot be echoed (no index): STATUSTEXT only.
Parameters flagged `not_armed` are refused while `armed()` says the vehicle is armed.
Accepted values are saved through the ParamStore at once (or, with `defer_saves`, marked due for the caller to
save off its control thread: `take_save`) (only values that differ from the defaults, as
PX4 does, so a later change of a default in fc_params.yaml reaches vehicles that never touched it).
Routing (the shell's job): the answer to PARAM_REQUEST_READ goes back to the requester; the PARAM_VALUE that
answers a PARAM_SET (accepted or refused) announces the value in force and is broadcast on every link, as
PX4 and ArduPilot do, so every connected GCS stays in sync; STATUSTEXT is broadcast.

Value encoding (mavlink_notes §2.3): REAL32 parameters travel as their float value. INT32 parameters are
encoded *bytewise* (the int32's four bytes copied into the float field) and the vehicle advertises
MAV_PROTOCOL_CAPABILITY_PARAM_ENCODE_BYTEWISE (`PARAM_ENCODING_CAPABILITY`, for AUTOPILOT_VERSION): QGC and
MAVSDK treat every non-ArduPilot autopilot as bytewise, so this is the encoding they decode correctly.
On PARAM_SET the sender's `param_type` says how the float was encoded: an integer type -> bytewise (QGC,
MAVSDK, pymavlink `mavset(..., parm_type=INT32)`), REAL32 -> the plain float value (MAVProxy's `param set`
and pymavlink's `param_set_send` default), which must then be integral for an INT32 parameter. The stored
type comes from our definitions, never from the message, and the value is decoded only by the type the
parameter is declared with: a REAL32 parameter takes only param_type REAL32 (an integer-typed set of a float
parameter, e.g. OL_ATT_K = NaN sent as INT8, which bytewise would read as 0, is refused, as PX4's
MavlinkParametersManager refuses a type mismatch). Caveat: MAVProxy's `param show` prints INT32
values raw (a tiny denormal float, e.g. 100 -> 1.4e-43); decode them with `decode_param_value`.
"""

from __future__ import annotations

import math
import struct
from collections import deque
from typing import Any, NamedTuple

from pymavlink.dialects.v20 import common as mavlink2

from navig8_fc.gcs.statustext import StatusTextEncoder
from navig8_fc.params.registry import MAX_NAME_LEN, ParamRegistry, SetResult
from navig8_fc.params.store import ParamStore

PARAM_ENCODING_CAPABILITY = mavlink2.MAV_PROTOCOL_CAPABILITY_PARAM_ENCODE_BYTEWISE

MAV_PARAM_TYPE_REAL32 = mavlink2.MAV_PARAM_TYPE_REAL32
MAV_PARAM_TYPE_INT32 = mavlink2.MAV_PARAM_TYPE_INT32
_WIRE_TYPE = {"REAL32": MAV_PARAM_TYPE_REAL32, "INT32": MAV_PARAM_TYPE_INT32}

# Bytewise layouts of the integer types inside the 4-byte float (little-endian, value in the low bytes).
_BYTEWISE_FORMAT = {
    mavlink2.MAV_PARAM_TYPE_UINT8: "<B3x",
    mavlink2.MAV_PARAM_TYPE_INT8: "<b3x",
    mavlink2.MAV_PARAM_TYPE_UINT16: "<H2x",
    mavlink2.MAV_PARAM_TYPE_INT16: "<h2x",
    mavlink2.MAV_PARAM_TYPE_UINT32: "<I",
    mavlink2.MAV_PARAM_TYPE_INT32: "<i",
}

# MAV_CMD_PREFLIGHT_STORAGE param1 (PARAM_STORAGE_ACTION; not in every pymavlink common.xml yet).
STORAGE_READ = 0
STORAGE_WRITE = 1
STORAGE_RESET = 2


class StoredLoad(NamedTuple):
    """Outcome of loading the parameter file into the registry."""

    ok: bool  # False: nothing usable in the file (reason says why); the registry was left unchanged
    applied: int  # stored values accepted
    refused: tuple[SetResult, ...]  # stored values the current definitions/rules refuse (the file is then unused)
    reason: str | None
    set_aside: str | None = None  # where an unusable file was moved to

    def report(self) -> list[str]:
        """What the operator is told (stderr at start, STATUSTEXT at the first ground-station contact)."""
        lines = [f"Stored {r.reason}" for r in self.refused]
        if self.reason:
            lines.append(self.reason)
        if self.set_aside:
            lines.append(f"Parameter file unusable: defaults in force; file kept as {self.set_aside}")
        return lines


def encode_param_value(value: float | int, param_type: int) -> float:
    """The float that goes into param_value: REAL32 as is, integer types bytewise."""
    fmt = _BYTEWISE_FORMAT.get(param_type)
    if fmt is None:
        return float(value)
    return struct.unpack("<f", struct.pack(fmt, int(value)))[0]


def decode_param_value(wire_value: float, param_type: int) -> float | int | None:
    """Inverse of encode_param_value; None for types a 4-byte float cannot carry (64-bit)."""
    if param_type == MAV_PARAM_TYPE_REAL32:
        return float(wire_value)
    fmt = _BYTEWISE_FORMAT.get(param_type)
    if fmt is None:
        return None
    raw = struct.pack("<f", wire_value)
    return struct.unpack(fmt, raw)[0]


def param_name(raw: str | bytes) -> str:
    """param_id as a str: up to the first NUL (absent when the name is exactly 16 chars), at most 16 chars."""
    if isinstance(raw, bytes | bytearray):
        raw = bytes(raw).decode("ascii", errors="replace")
    return raw.split("\0", 1)[0][:MAX_NAME_LEN]


def is_for_us(msg: Any, sysid: int, compid: int) -> bool:
    """Broadcast (0) or our system, and broadcast (0) or our component; messages without targets are for all."""
    ts = getattr(msg, "target_system", 0)
    tc = getattr(msg, "target_component", 0)
    return ts in (0, sysid) and tc in (0, compid)


class ParamProtocol:
    """Parameter microservice of one component (module docstring)."""

    def __init__(
        self,
        registry: ParamRegistry,
        mav: Any,
        store: ParamStore | None = None,
        *,
        sysid: int | None = None,
        compid: int | None = None,
        statustext: StatusTextEncoder | None = None,
        rate_per_s: float = 200.0,
        burst: int = 20,
        armed: Any = None,
        defer_saves: bool = False,
    ) -> None:
        """armed: a callable saying whether the vehicle is armed (not_armed parameters); None: never armed."""
        if not (rate_per_s > 0.0 and burst >= 1):
            raise ValueError("rate_per_s must be > 0 and burst >= 1")
        self._reg = registry
        self._mav = mav
        self._store = store
        self._sysid = int(mav.srcSystem if sysid is None else sysid)
        self._compid = int(mav.srcComponent if compid is None else compid)
        self._text = statustext or StatusTextEncoder(mav)
        self._rate_per_s = float(rate_per_s)
        self._burst = int(burst)
        self._lists: dict[Any, deque[int]] = {}  # requester -> indices still to send
        self._credit = float(burst)
        self._last_poll_s: float | None = None
        self._changes: list[SetResult] = []
        self._armed = armed if armed is not None else (lambda: False)
        self._defer_saves = bool(defer_saves)
        self._save_due = False

    # --- inbound -------------------------------------------------------------------------------------
    def handle(self, msg: Any, now_s: float, source: Any = None) -> list[Any]:
        """Replies to one inbound message (empty for messages that are not ours or not parameter messages).

        `source` identifies the requester of a PARAM_REQUEST_LIST (see `poll_routed`)."""
        kind = msg.get_type()
        if kind not in ("PARAM_REQUEST_LIST", "PARAM_REQUEST_READ", "PARAM_SET"):
            return []
        if not is_for_us(msg, self._sysid, self._compid):
            return []
        if kind == "PARAM_REQUEST_LIST":
            self._lists.pop(source, None)  # a restart goes to the back of the line
            self._lists[source] = deque(range(len(self._reg)))
            return []
        if kind == "PARAM_REQUEST_READ":
            return self._read(msg)
        return self._set(msg)

    def poll(self, now_s: float) -> list[Any]:
        """The next paced batch of the running list downloads (at most `burst`, `rate_per_s` on average)."""
        return [m for _, m in self.poll_routed(now_s)]

    def poll_routed(self, now_s: float) -> list[tuple[Any, Any]]:
        """Like `poll`, as (source, PARAM_VALUE): source is what `handle` got with the PARAM_REQUEST_LIST."""
        if self._last_poll_s is not None:
            elapsed = max(now_s - self._last_poll_s, 0.0)
            self._credit = min(float(self._burst), self._credit + elapsed * self._rate_per_s)
        self._last_poll_s = now_s
        out: list[tuple[Any, Any]] = []
        while self._lists and self._credit >= 1.0:
            source, queue = next(iter(self._lists.items()))
            n = min(int(self._credit), len(queue))
            self._credit -= n
            out += [(source, self.param_value_at(queue.popleft())) for _ in range(n)]
            if not queue:
                del self._lists[source]
        return out

    @property
    def list_remaining(self) -> int:
        """PARAM_VALUEs still to send for the running list downloads."""
        return sum(len(q) for q in self._lists.values())

    # --- PARAM_VALUE ---------------------------------------------------------------------------------
    def param_value(self, name: str) -> Any:
        return self.param_value_at(self._reg.index_of(name))

    def param_value_at(self, index: int) -> Any:
        d = self._reg.at_index(index)
        wire_type = _WIRE_TYPE[d.type]
        value = encode_param_value(self._reg.get(d.name), wire_type)
        return self._mav.param_value_encode(d.name.encode("ascii"), value, wire_type, len(self._reg), index)

    # --- persistence ---------------------------------------------------------------------------------
    def drain_changes(self) -> list[SetResult]:
        """Every set/load/reset outcome (accepted or refused) since the last call, for the log."""
        out, self._changes = self._changes, []
        return out

    def non_default_values(self) -> dict[str, float | int]:
        return {
            d.name: self._reg.get(d.name) for d in self._reg.definitions if self._reg.get(d.name) != d.coerce(d.default)
        }

    def save(self) -> str | None:
        """Write the current values to the store; the reason when that failed (None: saved or no store)."""
        if self._store is None:
            return None
        self._save_due = False
        return self.write_values(self.non_default_values())

    def write_values(self, values: dict[str, float | int]) -> str | None:
        """Write `values` to the store (any thread: touches only the store); the reason when that failed."""
        if self._store is None:
            return None
        try:
            self._store.save(values)
        except (OSError, ValueError) as exc:
            return f"parameters not saved: {exc}"
        return None

    @property
    def save_due(self) -> bool:
        return self._save_due and self._store is not None

    def take_save(self) -> dict[str, float | int] | None:
        """With defer_saves: the values to write when a save is due (then no longer due), else None."""
        if not self._save_due or self._store is None:
            return None
        self._save_due = False
        return self.non_default_values()

    def load_stored(self) -> StoredLoad:
        """Defaults, then the stored values (startup and PREFLIGHT_STORAGE read). No file: registry unchanged.
        A file is applied whole or not at all: when it cannot be read, or any known entry is refused by the
        current rules (a zero gain, a value the stability floor refuses), the registry is left as it was and
        the file is moved aside (store.set_aside); unknown names (a parameter since removed) are skipped."""
        if self._store is None:
            return StoredLoad(False, 0, (), "no parameter storage configured")
        if not self._store.exists() and not self._store.path.exists():
            return StoredLoad(False, 0, (), None)  # nothing stored yet: nothing to report
        values, reason = self._store.load()
        if reason is not None:
            aside = self._store.set_aside()
            return StoredLoad(False, 0, (), reason, str(aside) if aside else None)
        unknown = sorted(n for n in values if n not in self._reg)
        values = {n: v for n, v in values.items() if n in self._reg}
        before = self._reg.as_dict()
        self._reg.reset_defaults()
        results = self._reg.load_values(values)
        refused = tuple(r for r in results if not r.accepted)
        note = f"unknown stored parameters skipped: {', '.join(unknown)}" if unknown else None
        if refused:
            self._reg.restore(before)  # all or nothing: back to what was in force
            aside = self._store.set_aside()
            return StoredLoad(False, 0, refused, note, str(aside) if aside else None)
        self._changes.extend(results)
        self._record_reset(before, {r.name for r in results})
        return StoredLoad(True, len(results), (), note)

    def storage_command(self, action: int, armed: bool = False) -> tuple[int, list[Any]]:
        """MAV_CMD_PREFLIGHT_STORAGE param1: 0 read, 1 write, 2 reset to defaults -> (MAV_RESULT, messages)."""
        if action not in (STORAGE_READ, STORAGE_WRITE, STORAGE_RESET):
            return mavlink2.MAV_RESULT_DENIED, self._text.warning(
                f"PREFLIGHT_STORAGE: param1 {action} unsupported (0 read, 1 write, 2 reset)"
            )
        if action == STORAGE_WRITE:
            if self._store is None:
                return mavlink2.MAV_RESULT_FAILED, self._text.warning("No parameter storage configured")
            err = self.save()
            if err is not None:
                return mavlink2.MAV_RESULT_FAILED, self._text.warning(err)
            return mavlink2.MAV_RESULT_ACCEPTED, self._text.info("Parameters saved")
        if armed:
            verb = "load" if action == STORAGE_READ else "reset"
            return mavlink2.MAV_RESULT_DENIED, self._text.warning(f"Parameter {verb} denied: vehicle armed")
        before = self._reg.as_dict()
        if action == STORAGE_RESET:
            self._reg.reset_defaults()
            self._record_reset(before, set())
            msgs = self._changed_values(before)
            err = self.save()
            msgs += self._text.warning(err) if err else self._text.info("Parameters reset to defaults")
            return mavlink2.MAV_RESULT_ACCEPTED, msgs
        loaded = self.load_stored()
        if not loaded.ok:
            msgs = []
            for line in loaded.report() or ["no stored parameters"]:
                msgs += self._text.warning(f"Parameter load failed: {line}")
            return mavlink2.MAV_RESULT_FAILED, msgs
        msgs = self._changed_values(before)
        for line in loaded.report():
            msgs += self._text.warning(line)
        msgs += self._text.info(f"Parameters loaded ({loaded.applied} stored values)")
        return mavlink2.MAV_RESULT_ACCEPTED, msgs

    # --- internals -----------------------------------------------------------------------------------
    def _read(self, msg: Any) -> list[Any]:
        index = int(msg.param_index)
        if index == -1:
            name = param_name(msg.param_id)
            if name not in self._reg:
                return self._text.warning(f"PARAM_REQUEST_READ: unknown parameter {name!r}")
            return [self.param_value(name)]
        if not 0 <= index < len(self._reg):
            return self._text.warning(f"PARAM_REQUEST_READ: no parameter index {index} (0..{len(self._reg) - 1})")
        return [self.param_value_at(index)]

    def _set(self, msg: Any) -> list[Any]:
        name = param_name(msg.param_id)
        if name not in self._reg:
            return self._text.warning(f"PARAM_SET: unknown parameter {name!r}")
        value, why = self.decode_set(name, msg)
        if value is None:
            old = self._reg.get(name)
            result = SetResult(name, False, old, old, why)
        else:
            result = self._reg.set(name, value, armed=bool(self._armed()))
        self._changes.append(result)
        out = [self.param_value(name)]
        if not result.accepted:
            out += self._text.warning(result.reason or f"{name}: refused")
        elif result.value != result.old_value:
            if self._defer_saves:
                self._save_due = True
            else:
                err = self.save()
                if err is not None:
                    out += self._text.warning(f"{name} set, but {err}")
        return out

    def decode_set(self, name: str, msg: Any) -> tuple[float | int | None, str | None]:
        """A PARAM_SET's value, decoded only as the declared type allows (module docstring), or why not."""
        wire_type = int(msg.param_type)
        declared = self._reg.definition(name).type
        if declared == "REAL32" and wire_type != MAV_PARAM_TYPE_REAL32:
            return None, f"{name}: is REAL32, param_type {wire_type} refused"
        value = decode_param_value(float(msg.param_value), wire_type)
        if value is None:
            return None, f"{name}: param_type {wire_type} unsupported"
        return value, None

    def floor_needed(self, msg: Any) -> dict[str, float | int] | None:
        """For a PARAM_SET addressed to us: the candidate values whose stability floor is not computed yet
        (the registry's floor_needed), so the caller can compute it off its control thread first."""
        if msg.get_type() != "PARAM_SET" or not is_for_us(msg, self._sysid, self._compid):
            return None
        name = param_name(msg.param_id)
        if name not in self._reg:
            return None
        value, _ = self.decode_set(name, msg)
        if value is None:
            return None
        return self._reg.floor_needed(name, value, armed=bool(self._armed()))

    def refuse_set(self, msg: Any, why: str) -> list[Any]:
        """A PARAM_SET not processed (`why`: busy, not authorised): the value in force, nothing changed."""
        name = param_name(msg.param_id)
        if not is_for_us(msg, self._sysid, self._compid):
            return []
        if name not in self._reg:
            return self._text.warning(f"PARAM_SET {name!r}: {why}")
        return [self.param_value(name)] + self._text.warning(f"{name}: {why}")

    def apply_own(self, values: dict[str, float]) -> tuple[str | None, list[Any]]:
        """Values the FC measured itself (a calibration's): applied whole or not at all as a PARAM_SET would be
        (the registry's checks; while armed refused), saved like one, and the PARAM_VALUEs announcing them.
        Returns the refusal's reason (None: applied) and the messages to broadcast."""
        armed = bool(self._armed())
        for name, value in values.items():
            if (why := self._reg.validate(name, value, armed)) is not None:
                return f"{name} = {value:g}: {why}", []
        results = [self._reg.set(name, value, armed=armed) for name, value in values.items()]
        self._changes += results
        out = [self.param_value(n) for n in values]
        if any(r.value != r.old_value for r in results):
            if self._defer_saves:
                self._save_due = True
            elif (err := self.save()) is not None:
                out += self._text.warning(err)
        return None, out

    def _record_reset(self, before: dict[str, float | int], already: set[str]) -> None:
        for name, old in before.items():
            new = self._reg.get(name)
            if name not in already and new != old:
                self._changes.append(SetResult(name, True, new, old, None))

    def _changed_values(self, before: dict[str, float | int]) -> list[Any]:
        return [self.param_value(n) for n, old in before.items() if _differs(self._reg.get(n), old)]


def _differs(a: float | int, b: float | int) -> bool:
    return not (a == b or (isinstance(a, float) and isinstance(b, float) and math.isnan(a) and math.isnan(b)))

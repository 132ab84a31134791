"""MAVLink 2 message signing on the GCS-facing links (pymavlink's signing; docs/security.md).

PX4's model (docs.px4.io, "MAVLink Message Signing"): no key -> signing off, everything accepted, nothing signed;
a key -> every outgoing frame signed and every incoming frame must carry a valid signature (pymavlink checks the
HMAC and the per-stream timestamp, and raises on a bad or missing one: the link counts and drops it), except
RADIO_STATUS, which the MAVLink signing guide lets a receiver accept unsigned (a radio modem cannot sign).
SETUP_SIGNING sets the key: accepted unsigned only while no key is set; with a key, only a correctly signed one
gets through the link at all, so only a holder of the key can change or (all-zero key and timestamp) remove it.

The key lives in `<state-dir>/fc_signing_<N>.json` (hex, owner-only permissions, written atomically by the
shell's `signing_keys.KeyFile`, a `KeyStore` here), never in the log: the links hand the log a copy of every
SETUP_SIGNING with the key bytes zeroed (`redact_frame`), and the log records only "signing key set". The
signing timestamp starts at the wall clock (10 us units since 2015-01-01) and never goes back below the one
stored with the key.

Replays: the signing spec keeps a timestamp per stream (link id, system, component) that must strictly increase.
Both links check against one `StreamTable` (a frame captured on the GCS link is just as old on the API link), and
the table is saved beside the key (`checkpoint`, at shutdown) and restored at start, so a captured frame does not
replay after a restart either; a stream first seen after a restart must be newer than the last timestamp the FC
saw or sent before it (not merely within the spec's minute of grace).

pymavlink's own `check_signature` advances a stream's timestamp *before* it checks the HMAC, so one forged frame
with a far-future timestamp would lock the real ground station's stream out (every later genuine frame "old");
the links use `StreamTable.verify` instead: HMAC first, then the timestamp rules, then the update.
"""

from __future__ import annotations

import copy
import functools
import hashlib
import math
import threading
import time
from collections.abc import Iterable
from typing import Any, NamedTuple, Protocol

MSG_ID_SETUP_SIGNING = 256
MSG_ID_RADIO_STATUS = 109
ALLOWED_UNSIGNED = frozenset({MSG_ID_RADIO_STATUS})
KEY_LEN = 32
_EPOCH_2015_UNIX_S = 1420070400
_V2_HEADER_LEN = 10
_KEY_OFFSET = 10  # SETUP_SIGNING payload on the wire: initial_timestamp u64, target_system, target_component, key


def signing_timestamp(now_unix_s: float) -> int:
    """MAVLink signing time: 10 us units since 2015-01-01 00:00 UTC."""
    return max(0, int((now_unix_s - _EPOCH_2015_UNIX_S) * 100_000))


def _allow_unsigned(_mav: Any, msg_id: int) -> bool:
    return msg_id in ALLOWED_UNSIGNED


def redact_frame(frame: bytes) -> bytes:
    """`frame` with the key bytes of a MAVLink 2 SETUP_SIGNING zeroed (its CRC no longer matches: it is a log
    record, not a frame to parse); any other frame unchanged."""
    if len(frame) <= _V2_HEADER_LEN or frame[0] != 0xFD:
        return frame
    if int.from_bytes(frame[7:10], "little") != MSG_ID_SETUP_SIGNING:
        return frame
    n = frame[1]  # payload length (trailing zeros truncated)
    start = _V2_HEADER_LEN + _KEY_OFFSET
    end = _V2_HEADER_LEN + n
    if end <= start:
        return frame
    return frame[:start] + bytes(end - start) + frame[end:]


def redacted_message(msg: Any) -> Any:
    """A decoded SETUP_SIGNING for the log: a copy with the key zeroed; any other message itself."""
    if msg.get_type() != "SETUP_SIGNING":
        return msg
    red = copy.copy(msg)
    red.secret_key = [0] * KEY_LEN
    return red


NEW_STREAM_GRACE = 6_000_000  # 60 s in signing units: how far behind our timestamp a new stream may start
STREAMS_KEPT = 64  # streams remembered (only correctly signed frames make one); a forgotten one raises the floor
CHECKPOINT_PERIOD_S = 1.0  # the stream table is saved beside the key at most this often (and at shutdown)
StreamId = tuple[int, int, int]  # (link id as the sender signs it, system id, component id): the signing spec's stream


class StreamTable:
    """The last timestamp of every signed stream, one table for every link that shares the key, so a frame captured
    on one link is as old on the other. It survives a restart (saved beside the key): a stream it knows must go on
    from where it was; a stream it does not know must be newer than `new_stream_floor` (at start, the last
    timestamp the FC saw or sent before it stopped; raised when a stream is forgotten) and at most
    NEW_STREAM_GRACE behind the FC's own timestamp (the signing spec's one minute)."""

    def __init__(self) -> None:
        self.last: dict[StreamId, int] = {}
        self.new_stream_floor = 0
        self.changed = False  # since the last checkpoint

    def restore(self, streams: dict[StreamId, int], floor: int) -> None:
        self.last = dict(list(streams.items())[-STREAMS_KEPT:])
        self.new_stream_floor = max(int(floor), max(self.last.values(), default=0))

    def clear(self, floor: int) -> None:
        """A new key (or none): the old key's streams mean nothing; frames older than `floor` stay refused."""
        self.last = {}
        self.new_stream_floor = int(floor)
        self.changed = True

    def verify(self, mav: Any, msgbuf: bytearray, src_system: int, src_component: int) -> bool:
        """pymavlink's check_signature in a safe order (module docstring): HMAC first, then the timestamp rules
        (class docstring), then the update."""
        s = mav.signing
        h = hashlib.new("sha256")
        h.update(s.secret_key)
        h.update(msgbuf[:-6])
        if h.digest()[:6] != bytes(msgbuf[-6:]):
            return False
        timestamp = int.from_bytes(bytes(msgbuf[-12:-6]), "little")
        stream = (msgbuf[-13], src_system, src_component)
        last = self.last.get(stream)
        if last is not None:
            if timestamp <= last:
                return False
        elif timestamp <= self.new_stream_floor or timestamp + NEW_STREAM_GRACE < s.timestamp:
            return False
        elif len(self.last) >= STREAMS_KEPT:  # forget the stalest stream; nothing older than it gets back in
            stalest = min(self.last, key=self.last.__getitem__)
            self.new_stream_floor = max(self.new_stream_floor, self.last.pop(stalest))
        self.last[stream] = timestamp
        self.changed = True
        s.timestamp = max(s.timestamp, timestamp)
        return True


class StoredKey(NamedTuple):
    """What the key file holds: the key (None: no usable key), the last timestamp the FC saw or sent, the streams'
    last timestamps, and what the operator should know about the file (None: nothing)."""

    key: bytes | None
    timestamp: int
    streams: dict[StreamId, int]
    problem: str | None


class KeyStore(Protocol):
    """Where the key rests between runs (the FC's shell: `navig8_fc.shell.signing_keys.KeyFile`)."""

    def load(self) -> StoredKey: ...

    def save(self, key: bytes, timestamp: int, streams: dict[StreamId, int]) -> None:
        """Keep the key, its timestamp and the streams' timestamps; raises OSError on failure."""

    def remove(self) -> None: ...


class LinkSigning:
    """Signing state of the GCS-facing links (their pymavlink MAVLink objects pack and check the frames against one
    StreamTable)."""

    def __init__(self, mavs: Iterable[Any], key_file: KeyStore | None) -> None:
        self._mavs = list(mavs)
        self._file = key_file
        self.key_set = False
        self.streams = StreamTable()
        self._checkpoint_t = -math.inf
        self._writer: threading.Thread | None = None
        self.save_errors = 0  # checkpoints that could not be written (the next one tries again)

    @property
    def active(self) -> bool:
        return self.key_set

    def load(self) -> list[str]:
        """Apply a stored key with its streams (startup); what the operator should know."""
        if self._file is None:
            return []
        stored = self._file.load()
        if stored.key is not None and any(stored.key):
            self.streams.restore(stored.streams, stored.timestamp)
            self._apply(stored.key, stored.timestamp)
        return [stored.problem] if stored.problem else []

    def set_key(self, key: bytes, initial_timestamp: int) -> str:
        """SETUP_SIGNING: a new key (stored, applied to every link) or, all-zero key and timestamp, signing off.
        Returns the operator's message (never the key)."""
        if not any(key) and initial_timestamp == 0:
            for mav in self._mavs:
                mav.signing.secret_key = None
                mav.signing.sign_outgoing = False
                mav.signing.allow_unsigned_callback = None
            self._join_writer()
            if self._file is not None:
                self._file.remove()
            self.streams.clear(self._timestamp())
            self.key_set = False
            return "Signing disabled"
        if len(key) != KEY_LEN or not any(key):
            return "SETUP_SIGNING refused: the key must be 32 bytes, not all zero"
        self.streams.clear(self._timestamp())
        self._apply(key, initial_timestamp)
        if self._file is None:
            return "Signing key set (not stored: no --state-dir)"
        self._join_writer()
        try:
            self._save()
        except OSError as exc:
            return f"Signing key set, but not stored: {exc.strerror}"
        return "Signing key set"

    def checkpoint(self, now_s: float) -> None:
        """The stream table and timestamp saved beside the key when a stream moved, at most every
        CHECKPOINT_PERIOD_S of `now_s` (the caller's clock), by a worker thread (a file write with fsync does not
        belong between control steps). A crash loses at most that last period (docs/security.md)."""
        if (self._file is None or not self.key_set or not self.streams.changed
                or now_s - self._checkpoint_t < CHECKPOINT_PERIOD_S
                or (self._writer is not None and self._writer.is_alive())):
            return
        self._checkpoint_t = now_s
        self.streams.changed = False
        key, ts, streams = bytes(self._mavs[0].signing.secret_key), self._timestamp(), dict(self.streams.last)
        self._writer = threading.Thread(target=self._write, args=(key, ts, streams), name="signing-checkpoint",
                                        daemon=True)
        self._writer.start()

    def save_timestamp(self) -> None:
        """Keep the timestamp and the streams with the key (clean shutdown), so neither goes back after a
        restart."""
        self._join_writer()
        if self._file is not None and self.key_set:
            try:
                self._save()
            except OSError:
                self.save_errors += 1

    def _save(self) -> None:
        assert self._file is not None
        self._file.save(bytes(self._mavs[0].signing.secret_key), self._timestamp(), dict(self.streams.last))

    def _write(self, key: bytes, timestamp: int, streams: dict[StreamId, int]) -> None:
        assert self._file is not None
        try:
            self._file.save(key, timestamp, streams)
        except OSError:
            self.save_errors += 1
            self.streams.changed = True

    def _join_writer(self) -> None:
        if self._writer is not None:
            self._writer.join(timeout=5.0)
            self._writer = None

    def _timestamp(self) -> int:
        return max((m.signing.timestamp for m in self._mavs), default=0)

    def _apply(self, key: bytes, initial_timestamp: int) -> None:
        ts = max(int(initial_timestamp), signing_timestamp(time.time()), self._timestamp())
        for link_id, mav in enumerate(self._mavs):
            s = mav.signing
            s.secret_key = bytes(key)
            s.link_id = link_id
            s.timestamp = max(ts, s.timestamp)
            s.sign_outgoing = True
            s.allow_unsigned_callback = _allow_unsigned
            mav.check_signature = functools.partial(self.streams.verify, mav)
        self.key_set = True

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

pymavlink's own `check_signature` advances a stream's timestamp *before* it checks the HMAC, so one forged frame
with a far-future timestamp would lock the real ground station's stream out (every later genuine frame "old");
the links use `verify_signature` instead: HMAC first, then the timestamp rules, then the update.
"""

from __future__ import annotations

import copy
import hashlib
import time
import types
from collections.abc import Iterable
from typing import Any, Protocol

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


def verify_signature(mav: Any, msgbuf: bytearray, src_system: int, src_component: int) -> bool:
    """pymavlink's check_signature in a safe order (module docstring); the same rules otherwise: a stream's
    timestamps must increase, a new stream may be at most one minute behind our timestamp."""
    s = mav.signing
    h = hashlib.new("sha256")
    h.update(s.secret_key)
    h.update(msgbuf[:-6])
    if h.digest()[:6] != bytes(msgbuf[-6:]):
        return False
    timestamp = int.from_bytes(bytes(msgbuf[-12:-6]), "little")
    stream = (msgbuf[-13], src_system, src_component)
    last = s.stream_timestamps.get(stream)
    if (last is not None and timestamp <= last) or (last is None and timestamp + 6_000_000 < s.timestamp):
        return False
    s.stream_timestamps[stream] = timestamp
    s.timestamp = max(s.timestamp, timestamp)
    return True


class KeyStore(Protocol):
    """Where the key rests between runs (the FC's shell: `navig8_fc.shell.signing_keys.KeyFile`)."""

    def load(self) -> tuple[bytes | None, int, str | None]:
        """(key or None, timestamp, problem)."""

    def save(self, key: bytes, timestamp: int) -> None:
        """Keep the key and its timestamp; raises OSError on failure."""

    def remove(self) -> None: ...


class LinkSigning:
    """Signing state of the GCS-facing links (their pymavlink MAVLink objects pack and check the frames)."""

    def __init__(self, mavs: Iterable[Any], key_file: KeyStore | None) -> None:
        self._mavs = list(mavs)
        self._file = key_file
        self.key_set = False

    @property
    def active(self) -> bool:
        return self.key_set

    def load(self) -> list[str]:
        """Apply a stored key (startup); what the operator should know."""
        if self._file is None:
            return []
        key, ts, problem = self._file.load()
        if key is not None and any(key):
            self._apply(key, ts)
        return [problem] if problem else []

    def set_key(self, key: bytes, initial_timestamp: int) -> str:
        """SETUP_SIGNING: a new key (stored, applied to every link) or, all-zero key and timestamp, signing off.
        Returns the operator's message (never the key)."""
        if not any(key) and initial_timestamp == 0:
            for mav in self._mavs:
                mav.signing.secret_key = None
                mav.signing.sign_outgoing = False
                mav.signing.allow_unsigned_callback = None
            if self._file is not None:
                self._file.remove()
            self.key_set = False
            return "Signing disabled"
        if len(key) != KEY_LEN or not any(key):
            return "SETUP_SIGNING refused: the key must be 32 bytes, not all zero"
        self._apply(key, initial_timestamp)
        if self._file is None:
            return "Signing key set (not stored: no --state-dir)"
        try:
            self._file.save(key, self._timestamp())
        except OSError as exc:
            return f"Signing key set, but not stored: {exc.strerror}"
        return "Signing key set"

    def save_timestamp(self) -> None:
        """Keep the timestamp with the key (clean shutdown), so it never goes back after a restart."""
        if self._file is not None and self.key_set:
            key = self._mavs[0].signing.secret_key
            try:
                self._file.save(bytes(key), self._timestamp())
            except OSError:
                pass

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
            mav.check_signature = types.MethodType(verify_signature, mav)
        self.key_set = True

"""One MAVLink framer/parser for the messages Navig8 handles itself (the lockstep seam), built from the dialect.

    from navig8_fc.mavlink import codec
    c = codec.seam_codec()                                   # the seam's messages of the navig8 dialect
    enc = codec.Encoder(c, sysid=1, compid=25)
    frame = enc.frame("NAVIG8_SIM_STATUS", (1, 0, 1, 0.0, 0.0, 0))   # values in the message's field order
    for m in c.parse(frame, codec.ParseCounters()):          # -> [Message("NAVIG8_SIM_STATUS", keys, values, 1, 25, 0)]
        m.fields                                             # {"time_usec": 1, "step": 0, ...}

Each message's layout (`MessageSpec`) is read from the public metadata of the class mavgen generated for it
(msgname, id, crc_extra, fieldnames, fieldtypes, ordered_fieldnames, array_lengths); the struct format is
built from the C types and checked against the class's own. Decoded messages are plain records: `Message`
(name, field names and values in field order, arrays as tuples, source system/component, sequence; `.fields`
the name -> value dict). Packing takes the
field values in field order (`pack_values`) or a name -> value mapping (`pack_fields`).

Frames: MAVLink 2 (0xFD) and MAVLink 1 (0xFE) headers; MAVLink 2 payloads are written with trailing zero
bytes stripped (>= 1 byte kept) and zero-padded when read (a truncated payload); the CRC (X.25 with the
message's CRC_EXTRA) is checked. Signed frames are recognised by their incompat flag and skipped (counted:
nothing here verifies signatures), frames with an incompat flag we do not know are skipped (counted).
Whatever is wrong (bytes between frames, a truncated tail, a bad CRC, an id the codec was not asked to handle)
is counted in `ParseCounters` and dropped; nothing raises on input.

pymavlink stays the test oracle (tests/unit/test_codec.py: byte-identical frames, equal fields) and the
decoder for everything else (the GCS links keep pymavlink message objects for the gcs/ handlers).
"""

from __future__ import annotations

import functools
import hashlib
import hmac
import struct
from collections.abc import Iterable, Mapping, Sequence
from dataclasses import dataclass
from operator import itemgetter
from typing import Any, NamedTuple, Protocol

from navig8_fc.mavlink import dialect

V1_MAGIC, V2_MAGIC = 0xFE, 0xFD
V1_OVERHEAD, V2_OVERHEAD, SIGNATURE_LEN = 8, 12, 13
IFLAG_SIGNED = 0x01  # MAVLINK_IFLAG_SIGNED, the only incompat flag MAVLink 2 defines

# The messages the seam carries (docs/bridge.md), plus HEARTBEAT: the FC announces itself on the sim link with one.
SEAM_MESSAGES = ("ODOMETRY", "NAVIG8_ACTUATOR_STATE", "NAVIG8_ARM_STATE", "NAVIG8_TRUTH", "HIL_SENSOR",
                 "HIL_ACTUATOR_CONTROLS", "NAVIG8_ARM_CMD", "NAVIG8_SIM_STATUS", "HEARTBEAT")

# C type -> struct code (MAVLink is little endian); mavparse's uint8_t_mavlink_version is a uint8_t on the wire
_STRUCT_CODES = {"float": "f", "double": "d", "char": "s", "int8_t": "b", "uint8_t": "B",
                 "uint8_t_mavlink_version": "B",
                 "int16_t": "h", "uint16_t": "H", "int32_t": "i", "uint32_t": "I", "int64_t": "q", "uint64_t": "Q"}
_V2_HEADER = struct.Struct("<BBBBBBHB")  # the header after the magic byte (the part the CRC covers)


try:  # MAVLink's X.25 CRC (MCRF4XX, seed 0xFFFF by default) as pymavlink computes it when fastcrc is installed;
    # the C function itself, called for every frame
    from fastcrc.crc16 import mcrf4xx as crc16
except ImportError:  # pragma: no cover - pymavlink's own (slower) CRC
    def crc16(data: bytes) -> int:
        """MAVLink's X.25 CRC of data (seed 0xFFFF)."""
        return int(dialect.load().x25crc(data).crc)


class Message(NamedTuple):
    """A decoded frame: message name, its field names and values (field order, arrays as tuples), source system
    and component, sequence number. `fields` makes the name -> value dict; a hot path reads `values` by index
    (`MessageSpec.index`) and leaves the dict to whoever needs it (the log, after the step's answer is out)."""

    name: str
    keys: tuple[str, ...]
    values: tuple[Any, ...]
    sysid: int
    compid: int
    seq: int
    signed: bool = False  # the frame carried a MAVLink 2 signature that verified with the key `parse` was given

    @property
    def fields(self) -> dict[str, Any]:
        """A fresh name -> value dict, in field order."""
        return dict(zip(self.keys, self.values, strict=True))


class Counts(Protocol):
    """Where `Codec.parse` counts what it drops (ParseCounters, or a link's own counters with these names)."""

    garbage_bytes: int
    truncated: int
    bad_crc: int
    unknown_id: int
    signed: int
    bad_flags: int


@dataclass
class ParseCounters:
    """What `Codec.parse` dropped, summed over the datagrams it parsed."""

    garbage_bytes: int = 0  # bytes skipped looking for a frame start
    truncated: int = 0  # datagrams that end in part of a frame
    bad_crc: int = 0
    unknown_id: int = 0  # whole frames of ids this codec does not handle (their CRC cannot be checked)
    signed: int = 0  # signed frames (skipped: nothing verifies signatures here)
    bad_flags: int = 0  # MAVLink 2 frames with an incompat flag other than "signed"

    @property
    def bad_frames(self) -> int:
        """Frames dropped (truncated, bad CRC, unknown id, signed, bad flags); garbage bytes are not frames."""
        return self.truncated + self.bad_crc + self.unknown_id + self.signed + self.bad_flags


class MessageSpec:
    """The wire layout of one message, from its generated class (see the module docstring).

    Plain class: built once per message at load; pack_values and unpack_from are the codec's per-frame work."""

    __slots__ = ("name", "msg_id", "crc_extra", "crc_extra_byte", "fieldnames", "index", "struct", "size", "_plan",
                 "_reorder", "_group", "_simple")

    def __init__(self, cls: Any) -> None:
        self.name = str(cls.msgname)
        self.msg_id = int(cls.id)
        self.crc_extra = int(cls.crc_extra)
        self.crc_extra_byte = bytes((self.crc_extra,))
        names = [str(n) for n in cls.fieldnames]  # declaration order (the constructor's)
        wire = [str(n) for n in cls.ordered_fieldnames]  # wire order: by type size, extensions last
        types = dict(zip(names, cls.fieldtypes, strict=True))
        lengths = dict(zip(wire, (int(n) for n in cls.array_lengths), strict=True))
        if any(types[n] == "char" for n in names):
            raise ValueError(f"{self.name}: char fields are not handled by the codec (pymavlink decodes it)")
        fmt = "<" + "".join(f"{lengths[n] or ''}{_STRUCT_CODES[types[n]]}" for n in wire)
        if fmt != cls.unpacker.format:
            raise ValueError(f"{self.name}: layout {fmt} disagrees with the generated class's {cls.unpacker.format}")
        self.fieldnames = tuple(names)
        self.index = {n: i for i, n in enumerate(names)}  # field name -> position in Message.values
        self.struct = struct.Struct(fmt)
        self.size = self.struct.size
        # pack: the wire order as segments (start, stop, array length): a run of scalars that are neighbours in field
        # order too is one slice of the values (values[start:stop]), an array is values[start][:length]
        plan: list[list[int]] = []
        for n in wire:
            i = names.index(n)
            if lengths[n]:
                plan.append([i, i + 1, lengths[n]])
            elif plan and plan[-1][2] == 0 and plan[-1][1] == i:
                plan[-1][1] = i + 1
            else:
                plan.append([i, i + 1, 0])
        self._plan = tuple((a, b, k) for a, b, k in plan)
        self._simple = all(n == 0 for n in lengths.values())
        self._reorder = itemgetter(*(names.index(n) for n in wire)) if len(names) > 1 else (lambda v: (v[0],))
        # unpack: one key per field in field order, a slice for an array (itemgetter runs in C)
        pos, keys = 0, {}
        for n in wire:
            keys[n] = slice(pos, pos + lengths[n]) if lengths[n] else pos
            pos += lengths[n] or 1
        # None: the unpacked tuple is already one value per field in field order (no arrays, wire order = field order)
        self._group = (None if names == wire and self._simple else
                       itemgetter(*(keys[n] for n in names)) if len(names) > 1 else (lambda t: (t[keys[names[0]]],)))

    def pack_values(self, values: Sequence[Any]) -> bytes:
        """The full (untruncated) payload of field values given in field order; arrays as sequences of at
        least their length (extra elements are ignored, as pymavlink does)."""
        if self._simple:
            return self.struct.pack(*self._reorder(values))
        flat: list[Any] = []
        for a, b, n in self._plan:
            flat += values[a][:n] if n else values[a:b]
        return self.struct.pack(*flat)

    def pack_fields(self, fields: Mapping[str, Any]) -> bytes:
        return self.pack_values([fields[n] for n in self.fieldnames])

    def unpack(self, payload: bytes) -> dict[str, Any]:
        """Fields of a payload (zero-padded if shorter than the message, extra bytes ignored)."""
        return dict(zip(self.fieldnames, self.unpack_from(payload, 0, len(payload)), strict=True))

    def unpack_from(self, data: bytes, start: int, end: int) -> tuple[Any, ...]:
        """The field values (field order) of the payload data[start:end], read in place when it is whole."""
        if end - start >= self.size:
            t = self.struct.unpack_from(data, start)
        else:  # a truncated payload (MAVLink 2 strips trailing zeros): pad
            t = self.struct.unpack(data[start:end] + bytes(self.size - (end - start)))
        g = self._group
        return g(t) if g is not None else t


class Codec:
    """Framer/parser for a set of messages of the dialect (`SEAM_MESSAGES` by default)."""

    def __init__(self, names: Iterable[str] = SEAM_MESSAGES, module: Any = None) -> None:
        d = module if module is not None else dialect.load()
        self.specs: dict[str, MessageSpec] = {}
        self.by_id: dict[int, MessageSpec] = {}
        self._rejected = ParseCounters()  # decode_frame's: it answers None, nobody reads these
        for name in names:
            spec = MessageSpec(d.mavlink_map[getattr(d, f"MAVLINK_MSG_ID_{name}")])
            self.specs[spec.name] = spec
            self.by_id[spec.msg_id] = spec

    def frame(self, name: str, values: Sequence[Any], seq: int, sysid: int, compid: int) -> bytes:
        """One unsigned MAVLink 2 frame of `name` (values in field order), trailing payload zeros stripped."""
        return self.frames(((name, values),), seq, sysid, compid)

    def frames(self, records: Iterable[tuple[str, Sequence[Any]]], seq: int, sysid: int, compid: int,
               signing: FrameSigning | None = None) -> bytes:
        """Frames of (name, values) records back to back, sequence numbers seq, seq + 1, ... (mod 256); signed
        (MAVLink 2 signing, one timestamp each from `signing`) when given."""
        specs, hdr = self.specs, _V2_HEADER.pack
        flags = 0 if signing is None else IFLAG_SIGNED
        parts: list[bytes] = []
        for name, values in records:
            s = specs[name]
            payload = s.pack_values(values).rstrip(b"\0") or b"\0"
            body = hdr(len(payload), flags, 0, seq, sysid, compid, s.msg_id & 0xFFFF, s.msg_id >> 16) + payload
            frame = b"\xfd" + body + crc16(body + s.crc_extra_byte).to_bytes(2, "little")
            parts.append(frame if signing is None else signing.sign(frame))
            seq = (seq + 1) & 0xFF
        return b"".join(parts)

    def parse(self, data: bytes, counters: Counts, key: bytes | None = None) -> list[Message]:
        """The messages of one datagram, in order; everything else counted in `counters` and dropped. With `key`,
        signed frames whose signature verifies with it are decoded (`Message.signed`); without, or when it does not
        verify, a signed frame is counted (`signed`) and dropped. Unsigned frames decode either way."""
        return _scan(data, counters, self.by_id, key)

    def decode_frame(self, frame: bytes) -> Message | None:
        """The message of exactly one whole frame, or None (anything else in it, or a bad frame). A signed frame
        decodes without checking its signature: this reads the process's own frames back (for the log)."""
        if len(frame) > SIGNATURE_LEN and frame[0] == V2_MAGIC and frame[2] == IFLAG_SIGNED:
            frame = _unsigned(frame, self.by_id)
        got = self.parse(frame, self._rejected)
        return got[0] if len(got) == 1 and _frame_len(frame) == len(frame) else None


class FrameSigning:
    """MAVLink 2 signing of outgoing frames with one key (docs/bridge.md, "Authenticated bundles"): link id, a 48-bit
    timestamp that grows by one per frame (starting from `timestamp`), and the first 6 bytes of
    SHA-256(key + frame + link id + timestamp), as the MAVLink signing guide defines them."""

    def __init__(self, key: bytes, link_id: int = 0, timestamp: int = 1) -> None:
        if len(key) != 32:
            raise ValueError("a MAVLink 2 signing key is 32 bytes")
        self.key, self.link_id, self.timestamp = bytes(key), link_id & 0xFF, timestamp

    def sign(self, frame: bytes) -> bytes:
        """A whole frame built with the signed incompat flag (its CRC covers it) + its 13-byte signature block."""
        self.timestamp += 1
        tail = frame + bytes((self.link_id,)) + (self.timestamp & 0xFFFFFFFFFFFF).to_bytes(6, "little")
        return tail + hashlib.sha256(self.key + tail).digest()[:6]


def verify_frame(key: bytes, frame: bytes) -> bool:
    """A whole signed frame's signature against key (the timestamp is not judged here: the sim link's own step
    sequencing refuses replays)."""
    return hmac.compare_digest(hashlib.sha256(key + frame[:-6]).digest()[:6], frame[-6:])


def _unsigned(frame: bytes, by_id: dict[int, MessageSpec]) -> bytes:
    """A signed frame without its signature block, its incompat flag cleared and CRC recomputed (unknown id: as is)."""
    spec = by_id.get(frame[7] | (frame[8] << 8) | (frame[9] << 16))
    if spec is None:
        return frame
    body = frame[1:2] + b"\0" + frame[3:-SIGNATURE_LEN - 2]
    return b"\xfd" + body + crc16(body + spec.crc_extra_byte).to_bytes(2, "little")


def _frame_len(frame: bytes) -> int:
    if len(frame) < 3:
        return -1
    if frame[0] == V1_MAGIC:
        return V1_OVERHEAD + frame[1]
    return V2_OVERHEAD + frame[1] + (SIGNATURE_LEN if frame[2] & IFLAG_SIGNED else 0)


def _scan(data: bytes, counters: Counts, by_id: dict[int, MessageSpec] | None, key: bytes | None = None
          ) -> list[Any]:
    """The framer: each frame of a datagram by its own length fields (MAVLink 1 and 2, signed or not), bytes
    between frames and a truncated tail counted. by_id None: the frames' raw bytes (nothing checked beyond the
    lengths); else the decoded messages of the ids in by_id (CRC checked, the rest counted and dropped)."""
    out: list[Any] = []
    i, n = 0, len(data)
    while i < n:
        start = i
        if data[i] == V2_MAGIC:
            if i + 3 > n:
                counters.truncated += 1
                break
            flags = data[i + 2]
            end = i + V2_OVERHEAD + data[i + 1]
            i = end + SIGNATURE_LEN if flags & IFLAG_SIGNED else end
            v2 = True
        elif data[i] == V1_MAGIC:
            if i + 2 > n:
                counters.truncated += 1
                break
            end = i = i + V1_OVERHEAD + data[i + 1]
            flags, v2 = 0, False
        else:
            counters.garbage_bytes += 1
            i += 1
            continue
        if i > n:
            counters.truncated += 1
            break
        if by_id is None:
            out.append(bytes(data[start:i]))
            continue
        spec = by_id.get(data[start + 7] | (data[start + 8] << 8) | (data[start + 9] << 16) if v2
                         else data[start + 5])
        if spec is None:
            counters.unknown_id += 1
            continue
        if crc16(data[start + 1 : end - 2] + spec.crc_extra_byte) != data[end - 2] | (data[end - 1] << 8):
            counters.bad_crc += 1
            continue
        signed = False
        if flags:
            if flags & ~IFLAG_SIGNED:
                counters.bad_flags += 1
                continue
            if key is None or not verify_frame(key, data[start:i]):
                counters.signed += 1
                continue
            signed = True
        so = start + 4 if v2 else start + 2  # header: ..., seq, sysid, compid at so, so + 1, so + 2
        out.append(Message(spec.name, spec.fieldnames, spec.unpack_from(data, so + 6 if v2 else so + 4, end - 2),
                           data[so + 1], data[so + 2], data[so], signed))
    return out


def split_frames(data: bytes) -> tuple[list[bytes], int, int]:
    """The frames of a datagram (the codec's framer; no CRC check: the decoder checks it), the count of bytes
    skipped between frames, and 1 if the datagram ends in part of a frame. The GCS links split with this and
    decode each frame with pymavlink."""
    counts = ParseCounters()
    frames = _scan(data, counts, None)
    return frames, counts.garbage_bytes, counts.truncated


@dataclass
class Encoder:
    """Packs frames from one system/component and owns its sequence number (like a pymavlink MAVLink object)."""

    codec: Codec
    sysid: int
    compid: int
    seq: int = 0
    frames_out: int = 0
    bytes_out: int = 0
    signing: FrameSigning | None = None  # sign every frame (the sim link once paired: its session key)

    def frame(self, name: str, values: Sequence[Any]) -> bytes:
        """One frame; the sequence number advances (mod 256)."""
        out = self.codec.frames(((name, values),), self.seq, self.sysid, self.compid, self.signing)
        self.seq = (self.seq + 1) & 0xFF
        self.frames_out += 1
        self.bytes_out += len(out)
        return out

    def frame_fields(self, name: str, fields: Mapping[str, Any]) -> bytes:
        return self.frame(name, [fields[n] for n in self.codec.specs[name].fieldnames])

    def frames(self, records: Sequence[tuple[str, Sequence[Any]]]) -> bytes:
        """Frames of (name, values) records back to back (one datagram), one sequence number each."""
        out = self.codec.frames(records, self.seq, self.sysid, self.compid, self.signing)
        n = len(records)
        self.seq = (self.seq + n) & 0xFF
        self.frames_out += n
        self.bytes_out += len(out)
        return out


    def resign(self, data: bytes) -> bytes:
        """The frames of `data` (framed by this encoder, signed or not) signed with the current signing (unsigned
        without): a datagram built before a new session's key, re-sent in it."""
        out = []
        for frame in split_frames(data)[0]:
            if len(frame) > SIGNATURE_LEN and frame[0] == V2_MAGIC and frame[2] == IFLAG_SIGNED:
                frame = _unsigned(frame, self.codec.by_id)
            if self.signing is not None and frame[0] == V2_MAGIC and frame[2] == 0:
                spec = self.codec.by_id[frame[7] | (frame[8] << 8) | (frame[9] << 16)]
                body = frame[1:2] + bytes((IFLAG_SIGNED,)) + frame[3:-2]
                frame = self.signing.sign(b"\xfd" + body + crc16(body + spec.crc_extra_byte).to_bytes(2, "little"))
            out.append(frame)
        return b"".join(out)


@functools.cache
def seam_codec() -> Codec:
    """The codec for SEAM_MESSAGES (built once per process, like dialect.load())."""
    return Codec(SEAM_MESSAGES)


__all__ = ["SEAM_MESSAGES", "Codec", "Counts", "Encoder", "FrameSigning", "Message", "MessageSpec", "ParseCounters",
           "crc16", "seam_codec", "split_frames", "verify_frame"]

"""MCAP logging (DESIGN §7): one file per run, JSON channels with JSON schemas Foxglove can plot.

Resources (docs/logs.md, "Size cap and a full disk"): with `max_bytes` the file is closed (complete) and the log
continues in `<stem>.1.mcap`, `<stem>.2.mcap`, ... keeping the first part (the flight's start) and the newest
`keep_files` after it; a write that fails (disk full,
file-size limit, I/O error) stops the log: `error` says why, later records are dropped and counted (`dropped`),
and nothing raises into the caller's flight.

Chunks are small (64 KiB by default) so a killed process loses little; the file is sealed after every chunk
(mcap_writer: a provisional footer), so a file cut by a crash reads with the stock readers' defaults up to its last
complete chunk, and `read_mcap` also reads one cut in the middle of a write. Times: log_time = sim time (ns),
publish_time = the wall clock of the writer when given (the shell owns clocks; pass it in).
"""

from __future__ import annotations

import dataclasses
import functools
import json
import re
from collections.abc import Iterator, Mapping
from pathlib import Path
from typing import Any, BinaryIO

import orjson
from mcap.reader import NonSeekingReader

from navig8_fc.shell.mcap_writer import FastMcapWriter

CHUNK_SIZE = 64 * 1024


@functools.lru_cache(maxsize=256)
def _field_names(cls: type) -> tuple[str, ...]:
    return tuple(f.name for f in dataclasses.fields(cls))


_INF = float("inf")


def to_jsonable(obj: Any) -> Any:
    """Dataclasses, tuples, numpy arrays and scalars -> plain JSON types; non-finite floats -> None.

    Exact-type checks first: this runs for every logged record at 100 Hz, and isinstance/is_dataclass
    chains were the FC process's largest cost."""
    t = type(obj)
    if t is float:
        return obj if (obj == obj and obj != _INF and obj != -_INF) else None
    if t is int or t is bool or t is str or obj is None:
        return obj
    if t is tuple or t is list:
        return [to_jsonable(v) for v in obj]
    if t is dict:
        return {str(k): to_jsonable(v) for k, v in obj.items()}
    if hasattr(t, "__dataclass_fields__"):
        return {n: to_jsonable(getattr(obj, n)) for n in _field_names(t)}
    if hasattr(obj, "tolist"):  # numpy arrays and scalars
        return to_jsonable(obj.tolist())
    if isinstance(obj, Mapping):
        return {str(k): to_jsonable(v) for k, v in obj.items()}
    if isinstance(obj, (list, tuple)):
        return [to_jsonable(v) for v in obj]
    if isinstance(obj, float):
        return to_jsonable(float(obj))
    if isinstance(obj, int):
        return int(obj)
    return str(obj)


_ORJSON_OPTS = orjson.OPT_SERIALIZE_NUMPY | orjson.OPT_NON_STR_KEYS


def dumps_json(obj: Any) -> bytes:
    """Compact JSON bytes of a record: orjson serialises dataclasses, tuples and numpy natively and writes
    non-finite floats as null (as to_jsonable does); anything it cannot handle goes through to_jsonable."""
    try:
        return orjson.dumps(obj, option=_ORJSON_OPTS, default=to_jsonable)
    except (TypeError, orjson.JSONEncodeError):
        return orjson.dumps(to_jsonable(obj))


def json_schema_for(sample: Any) -> dict[str, Any]:
    """A JSON schema describing `sample` (already jsonable), so Foxglove knows the fields."""
    if isinstance(sample, bool):
        return {"type": "boolean"}
    if isinstance(sample, int):
        return {"type": "integer"}
    if isinstance(sample, float) or sample is None:
        return {"type": ["number", "null"]}
    if isinstance(sample, str):
        return {"type": "string"}
    if isinstance(sample, list):
        return {"type": "array", "items": json_schema_for(sample[0]) if sample else {}}
    if isinstance(sample, dict):
        return {"type": "object", "properties": {k: json_schema_for(v) for k, v in sample.items()}}
    return {}


def part_path(path: Path, k: int) -> Path:
    """Part k of a rotated log: the path itself for k = 0, else <stem>.<k><suffix>."""
    return path if k == 0 else path.with_name(f"{path.stem}.{k}{path.suffix}")


class McapLogger:
    """Writes JSON messages; a channel (and its schema, from the first message) per topic. Opening raises OSError
    (use `open_logger` for the reported form); after that no write raises (module docstring)."""

    def __init__(self, path: str | Path, chunk_size: int = CHUNK_SIZE, profile: str = "navig8", max_bytes: int = 0,
                 keep_files: int = 0) -> None:
        self.path = Path(path)
        self.path.parent.mkdir(parents=True, exist_ok=True)
        self.max_bytes, self.keep_files = int(max_bytes), int(keep_files)
        self._chunk_size, self._profile = chunk_size, profile
        self.error: str | None = None  # why the log stopped (None: writing)
        self.dropped = 0  # records not written since it stopped
        self.rotations = 0
        # what a new part must hold again so channel ids stay valid: schemas, channels and metadata, in order
        self._replay: list[tuple[str, tuple[Any, ...]]] = []
        self._fh: BinaryIO = open(self.path, "wb")  # noqa: SIM115 - closed in close()
        # FastMcapWriter: the library's file layout, byte for byte, at ~0.3 us per message instead of ~3 us (the FC
        # logs on the lockstep path). lz4 rather than zstd: 3x faster per chunk, files ~1.6x larger.
        self._w = self._start(self._fh)
        self._channels: dict[str, int] = {}
        self._raw_channels: dict[tuple[str, str], int] = {}
        self._schemas: dict[str, int] = {}
        self._closed = False

    def _start(self, fh: BinaryIO) -> FastMcapWriter:
        w = FastMcapWriter(fh, chunk_size=self._chunk_size, compression="lz4", sealed=True)  # a cut file reads
        w.start(profile=self._profile, library="navig8-sitl")
        return w

    @property
    def current_path(self) -> Path:
        return part_path(self.path, self.rotations)

    def fail(self, reason: str) -> None:
        """Stop logging (a write failed): keep the reason, drop and count from now on, release the file."""
        if self.error is None:
            self.error = reason
            try:
                self._fh.close()
            except OSError:
                pass  # the buffered tail cannot be written either; the complete chunks stay readable

    def maybe_rotate(self) -> None:
        """Start the next part once the current one has reached max_bytes (call it between steps)."""
        if self.max_bytes <= 0 or self.error is not None or self._closed:
            return
        try:
            if self._fh.tell() < self.max_bytes:
                return
            self._w.finish()
            self._fh.close()
            self.rotations += 1
            self._fh = open(self.current_path, "wb")  # noqa: SIM115 - closed in close()
            self._w = self._start(self._fh)
            for kind, args in self._replay:
                got = getattr(self._w, kind)(*args)
                assert kind == "add_metadata" or got is not None
            if self.keep_files > 0 and self.rotations > self.keep_files:  # part 0, the flight's start, stays
                part_path(self.path, self.rotations - self.keep_files).unlink(missing_ok=True)
        except OSError as e:
            self.fail(f"{e.strerror or e} ({self.current_path.name})")

    def channel(self, topic: str, sample: Any, schema_name: str | None = None, encoding: str = "json",
                schema: dict[str, Any] | None = None) -> int:
        if topic in self._channels:
            return self._channels[topic]
        name = schema_name or topic.strip("/").replace("/", ".")
        if name not in self._schemas:
            if encoding == "json":
                schema = dict(schema) if schema is not None else json_schema_for(sample)
                schema["title"] = name
                self._schemas[name] = self._register("register_schema", name, "jsonschema",
                                                     json.dumps(schema).encode())
            else:
                self._schemas[name] = self._register("register_schema", name, "", b"")
        cid = self._register("register_channel", topic, encoding, self._schemas[name])
        self._channels[topic] = cid
        return cid

    def _register(self, kind: str, *args: Any) -> Any:
        """A schema or channel record (kept for the next part: ids are positions, replayed in the same order)."""
        self._replay.append((kind, args))
        try:
            return getattr(self._w, kind)(*args)
        except OSError as e:
            self.fail(e.strerror or str(e))
            # the id it would have had: the caller's cached ids stay consistent (nothing more is written anyway)
            return sum(1 for k, _ in self._replay if k == kind)

    def _raw_channel(self, topic: str, encoding: str, peer: str) -> int:
        """A raw channel per (topic, peer): the peer rides in the channel's metadata, so each datagram keeps
        where it came from or went to at no cost per message (MCAP allows several channels on one topic)."""
        name = topic.strip("/").replace("/", ".") + ".raw"
        if name not in self._schemas:
            self._schemas[name] = self._register("register_schema", name, "", b"")
        parts = topic.strip("/").split("/")
        meta = {"peer": peer}
        if len(parts) == 3 and parts[0] == "mavlink":
            meta.update(link=parts[1], direction=parts[2])
        cid = self._register("register_channel", topic, encoding, self._schemas[name], meta)
        self._raw_channels[(topic, peer)] = cid
        return cid

    def log(self, topic: str, t_ns: int, obj: Any, publish_ns: int | None = None,
            schema: dict[str, Any] | None = None) -> None:
        cid = self._channels.get(topic)
        if cid is None:
            cid = self.channel(topic, to_jsonable(obj), schema=schema)
        self._add(cid, int(t_ns), dumps_json(obj), int(t_ns if publish_ns is None else publish_ns))

    def log_json(self, topic: str, t_ns: int, data: bytes, publish_ns: int | None = None) -> None:
        """A record already serialised by dumps_json: the same message as log(topic, t_ns, obj) (the channel's
        schema, on first use, from the record read back: the JSON types to_jsonable gives)."""
        cid = self._channels.get(topic)
        if cid is None:
            cid = self.channel(topic, orjson.loads(data))
        self._add(cid, int(t_ns), data, int(t_ns if publish_ns is None else publish_ns))

    def json_channel(self, topic: str, schema: dict[str, Any]) -> int:
        """The id of a JSON channel with this schema (registered on first use), for log_json_bytes."""
        cid = self._channels.get(topic)
        return cid if cid is not None else self.channel(topic, None, schema=schema)

    def log_json_bytes(self, channel_id: int, t_ns: int, data: bytes, publish_ns: int) -> None:
        """A record already serialised as JSON on a json_channel: the lean path for records logged every step."""
        if self.error is not None:
            self.dropped += 1
            return
        try:
            self._w.add_message(channel_id, t_ns, data, publish_ns)
        except OSError as e:
            self.dropped += 1
            self.fail(e.strerror or str(e))

    _add = log_json_bytes  # every message goes through here: dropped and counted once the log has stopped

    def log_raw(self, topic: str, t_ns: int, payload: bytes, publish_ns: int | None = None,
                encoding: str = "application/octet-stream", peer: str = "") -> None:
        """Raw bytes on `topic`; `peer` (e.g. "127.0.0.1:14550") goes to the channel's metadata."""
        cid = self._raw_channels.get((topic, peer))
        if cid is None:
            cid = self._raw_channel(topic, encoding, peer)
        self._add(cid, int(t_ns), payload, int(t_ns if publish_ns is None else publish_ns))

    def metadata(self, name: str, data: Any) -> None:
        """A metadata record; `data` is a mapping or a dataclass (values stored as JSON strings)."""
        d = to_jsonable(data)
        rec = {str(k): json.dumps(v) for k, v in d.items()}
        if self.rotations == 0:
            self._replay.append(("add_metadata", (name, rec)))  # the run's start (run, params) heads every part
        if self.error is not None:
            self.dropped += 1
            return
        try:
            self._w.add_metadata(name, rec)
        except OSError as e:
            self.fail(e.strerror or str(e))

    def close(self) -> None:
        if not self._closed:
            self._closed = True
            if self.error is None:
                try:
                    self._w.finish()
                    self._fh.close()
                except OSError as e:
                    self.fail(e.strerror or str(e))

    def __enter__(self) -> McapLogger:
        return self

    def __exit__(self, *exc: object) -> None:
        self.close()


def open_logger(path: Path | None, max_mb: float = 0.0, keep_files: int = 0) -> tuple[McapLogger | None, str | None]:
    """(logger, None), or (None, why) when the log cannot be opened (read-only directory, full disk): the caller
    reports it and runs without a log. No path: (None, None)."""
    if path is None:
        return None, None
    try:
        return McapLogger(path, max_bytes=int(max_mb * 1e6), keep_files=keep_files), None
    except OSError as e:
        return None, f"{e.strerror or e} ({path})"


def read_mcap(path: str | Path, topics: list[str] | None = None,
              skip_prefix: str | None = None) -> Iterator[tuple[str, int, Any]]:
    """(topic, log_time_ns, decoded JSON or raw bytes) in file order; a truncated file yields what its
    complete chunks hold and stops quietly. skip_prefix: topics starting with it are not decoded nor yielded."""
    for topic, t_ns, _pub, data in read_mcap_records(path, topics, skip_prefix):
        yield topic, t_ns, data


# An integer of 19 digits or more (2^63 has 19), which orjson reads as a float: JSON puts a number after a colon, a
# comma, a bracket, a minus sign or white space (a float's digits after its point or its exponent do not match).
_LONG_INTEGER = re.compile(rb"[:,\[\s-][0-9]{19}")


def decode_json(data: bytes) -> Any:
    """json.loads's objects, through orjson where it gives the same (0.6 of the CPU with the check below: a 30 s
    flight's log is ~12,000 messages, 0.65 s of json.loads when its summary is read back). Both round floats
    correctly and keep the keys' order; orjson reads an integer beyond 64 bits as a float, so a message that may hold
    one goes to json.loads, as does whatever orjson refuses (NaN or Infinity tokens)."""
    if not data[:1].isdigit() and _LONG_INTEGER.search(data) is None:
        try:
            return orjson.loads(data)
        except orjson.JSONDecodeError:
            pass
    return json.loads(data)


def read_mcap_records(path: str | Path, topics: list[str] | None = None,
                      skip_prefix: str | None = None) -> Iterator[tuple[str, int, int, Any]]:
    """Like read_mcap, with the publish time (the writer's wall clock, ns) as well."""
    with open(path, "rb") as fh:
        reader = NonSeekingReader(fh, validate_crcs=False)
        it = reader.iter_messages(topics=topics, log_time_order=False)
        while True:
            try:
                schema, channel, msg = next(it)
            except StopIteration:
                return
            except Exception:  # noqa: BLE001 - truncated or corrupt tail: stop at the last good record
                return
            if skip_prefix is not None and channel.topic.startswith(skip_prefix):
                continue
            if channel.message_encoding == "json":
                yield channel.topic, msg.log_time, msg.publish_time, decode_json(msg.data)
            else:
                yield channel.topic, msg.log_time, msg.publish_time, msg.data


def read_metadata(path: str | Path) -> dict[str, dict[str, Any]]:
    from mcap.reader import make_reader

    out: dict[str, dict[str, Any]] = {}
    with open(path, "rb") as fh:
        try:
            for rec in make_reader(fh).iter_metadata():
                out[rec.name] = {k: json.loads(v) for k, v in rec.metadata.items()}
        except Exception:  # noqa: BLE001 - truncated file: no summary, metadata unreachable this way
            pass
    return out

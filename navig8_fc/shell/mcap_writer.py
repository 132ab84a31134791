"""A small, fast MCAP writer: drop-in for the subset of `mcap.writer.Writer` that `mcap_log` uses.

Why this exists: the library's `Writer.add_message` costs ~3.3 us per message (a `Message` dataclass, several
`struct.pack` calls and `BytesIO` seeks per record), and the flight-controller process logs ~7-11 messages per
100 Hz control step on the critical path of the lockstep simulation. Here the per-message path is one precompiled
`struct.Struct.pack` plus two `bytearray` extends and one list append; everything derivable later (chunk and
file message counts, start/end times, per-channel counts) is computed when a chunk is finalised, from the
per-channel message index lists that MCAP needs anyway.

The output follows https://mcap.dev/spec and mirrors mcap-python 1.6.0's `Writer` with its default options
(chunked, all indexes, repeated schemas/channels, statistics, summary offsets, chunk CRCs, data-section CRC 0),
so that for the same calls and the same `library` string the two produce byte-identical files. That library's
readers (`make_reader`, `NonSeekingReader`, with CRC validation) are the test oracle.

Layout, as the library does it:
    magic, Header,
    [Metadata records, written straight to the data section when added],
    Chunk (Schema and Channel records land in the chunk open when they are registered, i.e. in or before the
    first chunk that uses them, so a sequential reader can decode every complete chunk of a truncated file;
    then Message records), its MessageIndex records (one per channel in the chunk, in first-message order), ...
    DataEnd (CRC 0), summary (Schemas, Channels, Statistics, ChunkIndexes, (no) AttachmentIndexes,
    MetadataIndexes, then one SummaryOffset per group), Footer (with summary CRC), magic.
A chunk is finalised as soon as its uncompressed size exceeds `chunk_size` (strictly, like the library).

Sealed (`sealed=True`, a seekable output): every write to the file after the header (a metadata record, a chunk
with its message indexes) goes out in one write together with a provisional end, DataEnd + a Footer without a
summary (summary_start 0) + magic, and the output is flushed and set back to before that end, which the next write
overwrites. A file cut at any moment (the process killed) therefore ends in a valid footer after its last complete
chunk, and the stock readers with their defaults (`mcap.reader.make_reader`: no summary, so it reads the data
section in order; Foxglove: an unindexed file) read it. `finish` writes the real end over the provisional one: a
finished file is byte-identical to an unsealed one.
"""

from __future__ import annotations

import struct
import zlib
from collections.abc import Callable, Sequence
from itertools import chain
from typing import BinaryIO

try:  # the chunk CRC (CRC-32/ISO-HDLC, zlib's): ~1.3 us per 64 KiB chunk instead of zlib's ~15 us
    from fastcrc.crc32 import iso_hdlc as _crc32
except ImportError:  # pragma: no cover - zlib's own
    _crc32 = zlib.crc32
from mcap.data_stream import RecordBuilder
from mcap.opcode import Opcode
from mcap.records import (
    Channel,
    ChunkIndex,
    DataEnd,
    Footer,
    Header,
    McapRecord,
    Metadata,
    MetadataIndex,
    Schema,
    Statistics,
    SummaryOffset,
)
from mcap.writer import CompressionType

try:
    import zstandard
except ImportError:  # pragma: no cover - optional, like in the library
    zstandard = None  # type: ignore[assignment]
try:
    import lz4.frame as lz4_frame
except ImportError:  # pragma: no cover
    lz4_frame = None  # type: ignore[assignment]

MCAP0_MAGIC = b"\x89MCAP0\r\n"

# Message record: opcode u8, record length u64, channel_id u16, sequence u32, log_time u64, publish_time u64.
_MESSAGE_HEADER = struct.Struct("<BQHIQQ")
_MESSAGE_FIXED_LEN = 2 + 4 + 8 + 8
_MESSAGE_OPCODE = int(Opcode.MESSAGE)
# Chunk record up to the compression string: opcode, record length, start, end, uncompressed size, crc, string len.
_CHUNK_HEADER = struct.Struct("<BQQQQII")
_U64 = struct.Struct("<Q")
# Footer fields as covered by the summary CRC: opcode, record length, summary_start, summary_offset_start.
_FOOTER_CRC_PREFIX = struct.Struct("<BQQQ")

_COMPRESSION_NAMES = {CompressionType.ZSTD: "zstd", CompressionType.LZ4: "lz4", CompressionType.NONE: ""}


def _provisional_end() -> bytes:
    """DataEnd, a Footer with no summary (summary_start = summary_offset_start = 0, CRC 0) and the closing magic."""
    rb = RecordBuilder()
    DataEnd(data_section_crc=0).write(rb)
    Footer(summary_start=0, summary_offset_start=0, summary_crc=0).write(rb)
    return rb.end() + MCAP0_MAGIC


PROVISIONAL_END = _provisional_end()


class FastMcapWriter:
    """Writes a chunked, indexed MCAP file to `output` (not closed by `finish`).

    :param output: a binary stream; only `write` is needed (`tell` is used once, if present, for offsets).
    :param chunk_size: a chunk is finalised once its uncompressed records exceed this many bytes.
    :param compression: "zstd", "lz4" or "" (none); a `mcap.writer.CompressionType` is accepted as well.
    """

    def __init__(
        self, output: BinaryIO, chunk_size: int = 64 * 1024, compression: str | CompressionType = "zstd",
        sealed: bool = False,
    ) -> None:
        if isinstance(compression, CompressionType):
            compression = _COMPRESSION_NAMES[compression]
        self._compress: Callable[[bytes], bytes] | None
        if compression == "zstd":
            if zstandard is None:
                raise RuntimeError("zstd compression requested but the zstandard package is not installed")
            self._compress = zstandard.compress
        elif compression == "lz4":
            if lz4_frame is None:
                raise RuntimeError("lz4 compression requested but the lz4 package is not installed")
            self._compress = lz4_frame.compress
        elif compression == "":
            self._compress = None
        else:
            raise ValueError(f"unsupported compression {compression!r} (use 'zstd', 'lz4' or '')")
        self._compression = compression
        self._compression_bytes = compression.encode()
        self._out = output
        self._pos = 0  # absolute offset of the next byte written to `output`
        self._chunk_size = chunk_size
        # The open chunk: its uncompressed records, and per channel (first-message order) [(log_time, offset)].
        self._buf = bytearray()
        self._index: dict[int, list[tuple[int, int]]] = {}
        self._schemas: dict[int, Schema] = {}
        self._channels: dict[int, Channel] = {}
        self._chunk_indexes: list[ChunkIndex] = []
        self._metadata_indexes: list[MetadataIndex] = []
        # Statistics accumulated per finalised chunk.
        self._message_count = 0
        self._channel_message_counts: dict[int, int] = {}
        self._start_time = 0
        self._end_time = 0
        self._finished = False
        self._sealed = sealed

    # -- non-hot records --------------------------------------------------------------------------------------

    def _write(self, data: bytes | bytearray) -> None:
        self._out.write(data)
        self._pos += len(data)

    def _write_sealed(self, data: bytes | bytearray) -> None:
        """`data`, and when sealed the provisional end after it in the same write, flushed, the output set back to
        before the end (module docstring)."""
        if not self._sealed:
            self._write(data)
            return
        self._out.write(bytes(data) + PROVISIONAL_END)
        self._out.flush()
        self._pos += len(data)
        self._out.seek(self._pos)

    def start(self, profile: str = "", library: str = "") -> None:
        """Writes the magic and the Header record."""
        tell = getattr(self._out, "tell", None)
        if tell is not None:
            try:
                self._pos = tell()
            except OSError:  # unseekable pipe: offsets relative to where we start
                self._pos = 0
        rb = RecordBuilder()
        Header(profile=profile, library=library).write(rb)
        self._write(MCAP0_MAGIC + rb.end())  # sealed with the first metadata record or chunk

    def register_schema(self, name: str, encoding: str, data: bytes) -> int:
        """Registers a schema (ids from 1) and writes it into the open chunk; returns its id."""
        schema_id = len(self._schemas) + 1
        schema = Schema(id=schema_id, data=data, encoding=encoding, name=name)
        self._schemas[schema_id] = schema
        self._add_to_chunk(schema)
        return schema_id

    def register_channel(
        self, topic: str, message_encoding: str, schema_id: int, metadata: dict[str, str] | None = None
    ) -> int:
        """Registers a channel (ids from 1, like the library; schema_id 0 = no schema) and writes it into the
        open chunk; returns its id."""
        channel_id = len(self._channels) + 1
        channel = Channel(
            id=channel_id,
            topic=topic,
            message_encoding=message_encoding,
            schema_id=schema_id,
            metadata=dict(metadata) if metadata else {},
        )
        self._channels[channel_id] = channel
        self._add_to_chunk(channel)
        return channel_id

    def _add_to_chunk(self, record: Schema | Channel) -> None:
        rb = RecordBuilder()
        record.write(rb)
        self._buf += rb.end()
        if self._index and len(self._buf) > self._chunk_size:
            self._finalize_chunk()

    def add_metadata(self, name: str, data: dict[str, str]) -> None:
        """Writes a Metadata record to the data section (outside chunks) and indexes it for the summary."""
        rb = RecordBuilder()
        Metadata(name=name, metadata=dict(data)).write(rb)
        record = rb.end()
        self._metadata_indexes.append(MetadataIndex(offset=self._pos, length=len(record), name=name))
        self._write_sealed(record)

    # -- hot path ---------------------------------------------------------------------------------------------

    def add_message(self, channel_id: int, log_time: int, data: bytes, publish_time: int, sequence: int = 0) -> None:
        """Appends a Message record to the open chunk; finalises the chunk once it exceeds chunk_size."""
        buf = self._buf
        index = self._index.get(channel_id)
        if index is None:
            index = self._index[channel_id] = []
        index.append((log_time, len(buf)))
        buf += _MESSAGE_HEADER.pack(
            _MESSAGE_OPCODE, _MESSAGE_FIXED_LEN + len(data), channel_id, sequence, log_time, publish_time
        )
        buf += data
        if len(buf) > self._chunk_size:
            self._finalize_chunk()

    # -- chunks and summary -----------------------------------------------------------------------------------

    def _finalize_chunk(self) -> None:
        index = self._index
        if not index:  # no messages: keep any schema/channel records for the next chunk, like the library
            return
        records = bytes(self._buf)
        self._buf = bytearray()
        self._index = {}

        n = 0
        start = end = -1
        counts = self._channel_message_counts
        for cid, entries in index.items():
            k = len(entries)
            n += k
            counts[cid] = counts.get(cid, 0) + k
            lo = min(entries)[0]
            hi = max(entries)[0]
            if start < 0 or lo < start:
                start = lo
            if hi > end:
                end = hi
        if self._message_count == 0:
            self._start_time = start
        elif start < self._start_time:
            self._start_time = start
        if end > self._end_time:
            self._end_time = end
        self._message_count += n

        data = self._compress(records) if self._compress is not None else records
        comp = self._compression_bytes
        chunk_start = self._pos
        header = _CHUNK_HEADER.pack(
            Opcode.CHUNK,
            8 + 8 + 8 + 4 + 4 + len(comp) + 8 + len(data),
            start,
            end,
            len(records),
            _crc32(records),
            len(comp),
        )
        chunk_length = len(header) + len(comp) + 8 + len(data)
        chunk_head = header + comp + _U64.pack(len(data))

        offsets: dict[int, int] = {}
        parts: list[bytes] = []
        pos = chunk_start + chunk_length
        for cid, entries in index.items():
            k = len(entries)
            offsets[cid] = pos
            part = struct.pack(
                f"<BQHI{2 * k}Q", Opcode.MESSAGE_INDEX, 6 + 16 * k, cid, 16 * k, *chain.from_iterable(entries)
            )
            parts.append(part)
            pos += len(part)
        message_indexes = b"".join(parts)
        if self._sealed:  # the chunk and its indexes in one write with the provisional end
            self._write_sealed(b"".join((chunk_head, data, message_indexes)))
        else:
            self._write(chunk_head)
            self._write(data)
            self._write(message_indexes)

        self._chunk_indexes.append(
            ChunkIndex(
                message_start_time=start,
                message_end_time=end,
                chunk_start_offset=chunk_start,
                chunk_length=chunk_length,
                message_index_offsets=offsets,
                message_index_length=len(message_indexes),
                compression=self._compression,
                compressed_size=len(data),
                uncompressed_size=len(records),
            )
        )

    def flush(self) -> None:
        """Finalises the open chunk (if it holds messages) and flushes the output stream."""
        self._finalize_chunk()
        self._out.flush()

    def finish(self) -> None:
        """Finalises the open chunk, writes DataEnd, the summary section, the Footer and the closing magic.
        Does not close the output stream."""
        if self._finished:
            return
        self._finished = True
        self._finalize_chunk()
        rb = RecordBuilder()
        DataEnd(data_section_crc=0).write(rb)  # the library writes 0 (data CRCs off by default)
        self._write(rb.end())

        summary_start = self._pos
        sb = RecordBuilder()
        offsets: list[SummaryOffset] = []

        def group(opcode: Opcode, records: Sequence[McapRecord]) -> None:
            group_start = sb.count
            for rec in records:
                rec.write(sb)
            offsets.append(SummaryOffset(opcode, summary_start + group_start, sb.count - group_start))

        stats = Statistics(
            attachment_count=0,
            channel_count=len(self._channels),
            channel_message_counts=self._channel_message_counts,
            chunk_count=len(self._chunk_indexes),
            message_count=self._message_count,
            metadata_count=len(self._metadata_indexes),
            message_start_time=self._start_time,
            message_end_time=self._end_time,
            schema_count=len(self._schemas),
        )
        group(Opcode.SCHEMA, list(self._schemas.values()))
        group(Opcode.CHANNEL, list(self._channels.values()))
        group(Opcode.STATISTICS, [stats])
        group(Opcode.CHUNK_INDEX, self._chunk_indexes)
        group(Opcode.ATTACHMENT_INDEX, [])  # the library writes an (empty) group offset for attachments too
        group(Opcode.METADATA_INDEX, self._metadata_indexes)
        summary_offset_start = summary_start + sb.count
        for off in offsets:
            off.write(sb)
        summary = sb.end()

        summary_crc = zlib.crc32(summary)
        summary_crc = zlib.crc32(
            _FOOTER_CRC_PREFIX.pack(Opcode.FOOTER, 8 + 8 + 4, summary_start, summary_offset_start), summary_crc
        )
        fb = RecordBuilder()
        Footer(summary_start=summary_start, summary_offset_start=summary_offset_start, summary_crc=summary_crc).write(
            fb
        )
        self._write(summary + fb.end() + MCAP0_MAGIC)


__all__ = ["FastMcapWriter", "MCAP0_MAGIC"]

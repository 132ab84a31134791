"""FastMcapWriter against the oracle: mcap-python's own Writer and readers (CRC-validating)."""

from __future__ import annotations

import io
import json
import random
from pathlib import Path
from typing import Any

import lz4.frame
import pytest
import zstandard
from mcap.data_stream import ReadDataStream
from mcap.opcode import Opcode
from mcap.reader import NonSeekingReader, make_reader
from mcap.records import Channel, Chunk, Message, MessageIndex, Schema
from mcap.stream_reader import StreamReader, breakup_chunk
from mcap.writer import CompressionType, Writer

from navig8_fc.shell.mcap_log import read_mcap
from navig8_fc.shell.mcap_writer import FastMcapWriter

_LIB_COMPRESSION = {"zstd": CompressionType.ZSTD, "lz4": CompressionType.LZ4, "": CompressionType.NONE}
COMPRESSIONS = ["zstd", "lz4", ""]
CHUNK = 8 * 1024


def _script(w: Any, n: int = 2500, seed: int = 7) -> list[tuple[str, int, int, int, bytes]]:
    """Drives a writer (library or ours) through the same calls; returns what was written, in order, as
    (topic, log_time, publish_time, sequence, data)."""
    rnd = random.Random(seed)
    w.start(profile="navig8", library="navig8-sitl")
    s_state = w.register_schema("state", "jsonschema", b'{"type": "object"}')
    s_att = w.register_schema("att", "jsonschema", b'{"type": "object", "title": "att"}')
    s_raw = w.register_schema("mavlink.raw", "", b"")  # how mcap_log registers raw channels
    topics: dict[int, tuple[str, str]] = {}
    cid = w.register_channel("/state", "json", s_state)
    topics[cid] = ("/state", "json")
    cid = w.register_channel("/att", "json", s_att, {"rate": "100"})
    topics[cid] = ("/att", "json")
    cid = w.register_channel("/mavlink/raw", "application/octet-stream", s_raw)
    topics[cid] = ("/mavlink/raw", "raw")
    cid = w.register_channel("/blob", "application/octet-stream", 0)  # schemaless
    topics[cid] = ("/blob", "raw")
    w.add_metadata("params", {"INDI_K": "0.5", "MODE": '"hover"'})
    written = []
    for i in range(n):
        if i == n // 2:  # a channel registered mid-run, after some chunks, and a second metadata record
            cid = w.register_channel("/late", "json", s_state)
            topics[cid] = ("/late", "json")
            w.add_metadata("late", {"at": str(i)})
        cid = rnd.choice(sorted(topics))
        topic, kind = topics[cid]
        t = 1_000_000 + i * 10_000 + rnd.randint(-25_000, 25_000)  # slightly out of order
        if kind == "json":
            data = json.dumps({"i": i, "v": [rnd.random() for _ in range(rnd.randint(0, 12))]}).encode()
        else:
            data = bytes(rnd.getrandbits(8) for _ in range(rnd.randint(0, 260)))
        pub = t + rnd.randint(0, 999)
        w.add_message(cid, t, data, pub, i)
        written.append((topic, t, pub, i, data))
    w.finish()
    return written


def _write_both(compression: str, **kw: Any) -> tuple[bytes, bytes, list[tuple[str, int, int, int, bytes]]]:
    lib, fast = io.BytesIO(), io.BytesIO()
    expected = _script(Writer(lib, chunk_size=CHUNK, compression=_LIB_COMPRESSION[compression]), **kw)
    assert _script(FastMcapWriter(fast, chunk_size=CHUNK, compression=compression), **kw) == expected
    return lib.getvalue(), fast.getvalue(), expected


@pytest.fixture(scope="module", params=COMPRESSIONS, ids=["zstd", "lz4", "none"])
def files(request: pytest.FixtureRequest) -> tuple[str, bytes, bytes, list[tuple[str, int, int, int, bytes]]]:
    return (request.param, *_write_both(request.param))


def _msgs(data: bytes, **kw: Any) -> list[tuple[Schema | None, Channel, Message]]:
    return [tuple(m) for m in make_reader(io.BytesIO(data), validate_crcs=True).iter_messages(**kw)]


def test_seeking_reader_sees_the_same_file(files: tuple[str, bytes, bytes, list]) -> None:
    compression, lib, fast, expected = files
    s_lib = make_reader(io.BytesIO(lib), validate_crcs=True).get_summary()
    s_fast = make_reader(io.BytesIO(fast), validate_crcs=True).get_summary()
    assert s_lib is not None and s_fast is not None
    st, sl = s_fast.statistics, s_lib.statistics
    assert st is not None and sl is not None
    assert st.message_count == sl.message_count == len(expected)
    assert st.channel_message_counts == sl.channel_message_counts
    assert sum(st.channel_message_counts.values()) == len(expected)
    assert st.chunk_count == sl.chunk_count == len(s_fast.chunk_indexes) >= 5
    assert (st.message_start_time, st.message_end_time) == (sl.message_start_time, sl.message_end_time)
    assert st.message_start_time == min(e[1] for e in expected)
    assert st.message_end_time == max(e[1] for e in expected)
    assert (st.schema_count, st.channel_count, st.metadata_count) == (3, 5, 2)
    assert s_fast.schemas == s_lib.schemas and s_fast.channels == s_lib.channels
    assert s_fast.chunk_indexes == s_lib.chunk_indexes
    assert {c.compression for c in s_fast.chunk_indexes} == {compression}
    assert s_fast.channels[4].schema_id == 0
    # every message, with its schema and channel, in file order and in log-time order
    plain = _msgs(fast, log_time_order=False)
    assert plain == _msgs(lib, log_time_order=False)
    assert [(c.topic, m.log_time, m.publish_time, m.sequence, m.data) for _, c, m in plain] == expected
    assert [s is None for s, c, _ in plain] == [c.topic == "/blob" for _, c, _ in plain]
    ordered = _msgs(fast)  # log_time_order=True is the default
    assert ordered == _msgs(lib)
    assert [m.log_time for _, _, m in ordered] == sorted(e[1] for e in expected)
    # topic + time filters go through the chunk and message indexes
    t0, t1 = 6_000_000, 14_000_000
    kw = {"topics": ["/att", "/late", "/blob"], "starting_at": t0, "ending_before": t1}
    filtered = _msgs(fast, **kw)
    assert filtered == _msgs(lib, **kw)
    want = sorted((e[1], e[3]) for e in expected if e[0] in kw["topics"] and t0 <= e[1] < t1)
    assert [(m.log_time, m.sequence) for _, _, m in filtered] == want and len(want) > 50
    # metadata
    meta = list(make_reader(io.BytesIO(fast), validate_crcs=True).iter_metadata())
    assert meta == list(make_reader(io.BytesIO(lib), validate_crcs=True).iter_metadata())
    assert [(m.name, m.metadata) for m in meta] == [
        ("params", {"INDI_K": "0.5", "MODE": '"hover"'}),
        ("late", {"at": str(len(expected) // 2)}),
    ]
    header = make_reader(io.BytesIO(fast)).get_header()
    assert (header.profile, header.library) == ("navig8", "navig8-sitl")


def test_byte_identical_to_library(files: tuple[str, bytes, bytes, list]) -> None:
    _, lib, fast, _ = files
    assert fast == lib


def test_non_seeking_reader_and_chunk_layout(files: tuple[str, bytes, bytes, list]) -> None:
    _, _, fast, expected = files
    got = NonSeekingReader(io.BytesIO(fast), validate_crcs=True).iter_messages(log_time_order=False)
    assert [(c.topic, m.log_time, m.publish_time, m.sequence, m.data) for _, c, m in got] == expected
    # each chunk carries the schemas/channels not seen before that its messages need
    known_schemas: set[int] = set()
    known_channels: dict[int, int] = {}
    n_chunks = 0
    for rec in StreamReader(io.BytesIO(fast), emit_chunks=True).records:
        if not isinstance(rec, Chunk):
            continue
        n_chunks += 1
        for r in breakup_chunk(rec, validate_crc=True):
            if isinstance(r, Schema):
                known_schemas.add(r.id)
            elif isinstance(r, Channel):
                known_channels[r.id] = r.schema_id
            else:
                assert r.channel_id in known_channels
                assert known_channels[r.channel_id] in known_schemas | {0}
    assert n_chunks >= 5 and len(known_channels) == 5 and known_schemas == {1, 2, 3}


def test_message_indexes(files: tuple[str, bytes, bytes, list]) -> None:
    """The Python seeking reader only uses ChunkIndexes, so check the MessageIndex records directly: those
    after each chunk, and those the ChunkIndex points at, list each message's (log_time, offset) in the
    uncompressed chunk, per channel."""
    _, _, fast, expected = files
    summary = make_reader(io.BytesIO(fast)).get_summary()
    assert summary is not None
    chunks: list[tuple[dict[int, list[tuple[int, int]]], list[MessageIndex]]] = []
    for rec in StreamReader(io.BytesIO(fast), emit_chunks=True).records:
        if isinstance(rec, Chunk):
            data = rec.data
            if rec.compression == "zstd":
                data = zstandard.decompress(data, rec.uncompressed_size)
            elif rec.compression == "lz4":
                data = lz4.frame.decompress(data)
            by_channel: dict[int, list[tuple[int, int]]] = {}
            pos = 0
            while pos < len(data):  # walk the records by hand: opcode u8, length u64
                opcode, length = data[pos], int.from_bytes(data[pos + 1 : pos + 9], "little")
                if opcode == Opcode.MESSAGE:
                    cid = int.from_bytes(data[pos + 9 : pos + 11], "little")
                    log_time = int.from_bytes(data[pos + 15 : pos + 23], "little")
                    by_channel.setdefault(cid, []).append((log_time, pos))
                pos += 9 + length
            chunks.append((by_channel, []))
        elif isinstance(rec, MessageIndex):
            chunks[-1][1].append(rec)
    assert len(chunks) == len(summary.chunk_indexes)
    assert sum(len(v) for by_channel, _ in chunks for v in by_channel.values()) == len(expected)
    for (by_channel, indexes), ci in zip(chunks, summary.chunk_indexes, strict=True):
        assert {i.channel_id: i.records for i in indexes} == by_channel
        assert set(ci.message_index_offsets) == set(by_channel)
        first = min(ci.message_index_offsets.values())
        assert first == ci.chunk_start_offset + ci.chunk_length
        for cid, offset in ci.message_index_offsets.items():
            stream = ReadDataStream(io.BytesIO(fast[offset:]))
            assert stream.read1() == Opcode.MESSAGE_INDEX
            stream.read8()
            assert MessageIndex.read(stream).records == by_channel[cid]
        last = max(ci.message_index_offsets.values())
        assert last + 9 + int.from_bytes(fast[last + 1 : last + 9], "little") == first + ci.message_index_length
        times = [t for v in by_channel.values() for t, _ in v]
        assert (ci.message_start_time, ci.message_end_time) == (min(times), max(times))


def test_truncated_file_yields_complete_chunks(tmp_path: Path) -> None:
    _, fast, expected = _write_both("lz4", n=1500)
    summary = make_reader(io.BytesIO(fast)).get_summary()
    assert summary is not None
    last = summary.chunk_indexes[-1]
    # messages per chunk, counted by the library's chunk decoder
    per_chunk = [
        sum(isinstance(r, Message) for r in breakup_chunk(rec, validate_crc=True))
        for rec in StreamReader(io.BytesIO(fast), emit_chunks=True).records
        if isinstance(rec, Chunk)
    ]
    assert len(per_chunk) == len(summary.chunk_indexes) >= 3 and sum(per_chunk) == len(expected)
    p = tmp_path / "cut.mcap"
    p.write_bytes(fast[: last.chunk_start_offset + last.chunk_length // 2])
    got = list(read_mcap(p))
    keep = expected[: len(expected) - per_chunk[-1]]
    assert len(got) == len(keep) > 0
    for (topic, t, data), (e_topic, e_t, _pub, _seq, e_data) in zip(got, keep, strict=True):
        assert (topic, t) == (e_topic, e_t)
        assert data == (e_data if topic in ("/mavlink/raw", "/blob") else json.loads(e_data))


@pytest.mark.parametrize("compression", COMPRESSIONS)
def test_no_messages(compression: str) -> None:
    out, lib = io.BytesIO(), io.BytesIO()
    for w in (FastMcapWriter(out, compression=compression), Writer(lib, compression=_LIB_COMPRESSION[compression])):
        w.start(library="x")
        w.register_channel("/a", "json", w.register_schema("a", "jsonschema", b"{}"))
        w.finish()
    assert out.getvalue() == lib.getvalue()
    reader = make_reader(io.BytesIO(out.getvalue()), validate_crcs=True)
    summary = reader.get_summary()
    assert summary is not None and summary.statistics is not None
    assert summary.statistics.message_count == 0 and summary.statistics.chunk_count == 0
    assert [c.topic for c in summary.channels.values()] == ["/a"]
    assert list(reader.iter_messages()) == []
    assert list(NonSeekingReader(io.BytesIO(out.getvalue()), validate_crcs=True).iter_messages()) == []
    # nothing at all registered
    bare = io.BytesIO()
    w = FastMcapWriter(bare)
    w.start()
    w.finish()
    assert list(make_reader(io.BytesIO(bare.getvalue()), validate_crcs=True).iter_messages()) == []


def test_large_message_and_out_of_order_times() -> None:
    out, lib = io.BytesIO(), io.BytesIO()
    big = bytes(range(256)) * 40  # 10 KiB > chunk_size
    times = [500, 100, 900, 50, 700, 3000, 20]
    for w in (FastMcapWriter(out, chunk_size=1024), Writer(lib, chunk_size=1024)):
        w.start(library="x")
        c = w.register_channel("/raw", "application/octet-stream", w.register_schema("raw", "", b""))
        d = w.register_channel("/j", "json", 0)
        for k, t in enumerate(times):
            w.add_message(c if k % 2 else d, t, big if k == 2 else b"{}", t + 1, k)
        w.finish()
    assert out.getvalue() == lib.getvalue()
    reader = make_reader(io.BytesIO(out.getvalue()), validate_crcs=True)
    summary = reader.get_summary()
    assert summary is not None and summary.statistics is not None
    st = summary.statistics
    assert (st.message_start_time, st.message_end_time, st.message_count) == (20, 3000, len(times))
    assert st.channel_message_counts == {1: 3, 2: 4}
    big_chunks = [ci for ci in summary.chunk_indexes if ci.uncompressed_size > len(big)]
    assert len(big_chunks) == 1 and big_chunks[0].message_start_time <= 900 <= big_chunks[0].message_end_time
    msgs = [m for _, _, m in reader.iter_messages(log_time_order=True)]
    assert [m.log_time for m in msgs] == sorted(times)
    assert [m.data for m in msgs if m.log_time == 900] == [big]
    assert [
        m.sequence for _, _, m in NonSeekingReader(io.BytesIO(out.getvalue())).iter_messages(log_time_order=False)
    ] == list(range(len(times)))


def test_rejects_unknown_compression() -> None:
    with pytest.raises(ValueError):
        FastMcapWriter(io.BytesIO(), compression="gzip")


def test_a_sealed_file_cut_at_any_moment_reads_with_the_stock_readers_defaults(tmp_path: Path) -> None:
    """Sealed: after every chunk or metadata record the file on disk ends in a provisional footer, so a copy taken
    at that moment (what a killed process leaves) reads with make_reader's defaults, every message written so far
    in a complete chunk; finished, the file is byte-identical to an unsealed one."""
    sealed_path = tmp_path / "sealed.mcap"
    plain = io.BytesIO()
    cuts: list[tuple[bytes, int]] = []  # (the file on disk, messages in complete chunks by then)
    with open(sealed_path, "wb") as fh:
        writers = [FastMcapWriter(fh, chunk_size=2048, compression="lz4", sealed=True),
                   FastMcapWriter(plain, chunk_size=2048, compression="lz4")]
        for w in writers:
            w.start(profile="navig8", library="navig8-sitl")
            w.add_metadata("run", {"scenario": "hover"})
            sid = w.register_schema("x", "jsonschema", b"{}")
            w.register_channel("/x", "json", sid)
        for i in range(500):
            for w in writers:
                w.add_message(1, i, json.dumps({"i": i, "pad": "p" * (i % 37)}).encode(), i)
            if i % 7 == 0:
                cuts.append((sealed_path.read_bytes(), i))
        writers[0].finish()
        writers[1].finish()
    assert sealed_path.read_bytes() == plain.getvalue()
    n_read = []
    for cut, last_i in cuts:
        with io.BytesIO(cut) as fh:
            got = [json.loads(m.data)["i"] for _s, _c, m in make_reader(fh).iter_messages()]
        assert got == list(range(len(got))) and len(got) <= last_i + 1  # in order, none invented
        n_read.append(len(got))
    assert n_read == sorted(n_read) and n_read[-1] > 400  # what the complete chunks hold, growing

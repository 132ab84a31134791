"""navig8-log repair: rewrite an MCAP log cut by a crash into a whole, indexed file (docs/logs.md, "A cut log").

    navig8-log repair CUT.mcap [-o OUT.mcap]      # default OUT: CUT.repaired.mcap

navig8-fc's logs are sealed after every chunk, so a log cut between two writes already reads with the stock readers'
defaults; one cut in the middle of a write (or written by an older version) ends in a partial record, and the stock
`make_reader(...).iter_messages()` raises on it ("expected footer at end of MCAP file"). This reads the file in order
up to its last complete record (schemas, channels with their metadata, messages, metadata records) and writes them
again with the mcap library's own Writer (chunked, indexed, summary and footer), so every reader opens the result.
Exit 0 with a one-line report; 1 when the input is not an MCAP file at all; 2 on a usage error.
"""

from __future__ import annotations

import argparse
import sys
from dataclasses import dataclass
from pathlib import Path

from mcap.exceptions import McapError
from mcap.records import Channel, Chunk, Footer, Header, Message, Metadata, Schema
from mcap.stream_reader import StreamReader, breakup_chunk
from mcap.writer import CompressionType, Writer


@dataclass(frozen=True)
class Repaired:
    """What a repair kept: message, channel and metadata counts, and whether the input was whole already."""

    messages: int
    channels: int
    metadata: int
    input_was_complete: bool


class _Copier:
    """Records in file order -> the library's Writer, schema and channel ids mapped to the new file's."""

    def __init__(self, out: Writer) -> None:
        self.out = out
        self.schemas: dict[int, int] = {0: 0}
        self.channels: dict[int, int] = {}
        self.messages = self.metadata = 0

    def record(self, rec: object) -> None:
        if isinstance(rec, Chunk):
            for inner in breakup_chunk(rec, validate_crc=True):
                self.record(inner)
        elif isinstance(rec, Schema) and rec.id not in self.schemas:
            self.schemas[rec.id] = self.out.register_schema(rec.name, rec.encoding, rec.data)
        elif isinstance(rec, Channel) and rec.id not in self.channels:
            self.channels[rec.id] = self.out.register_channel(rec.topic, rec.message_encoding,
                                                              self.schemas.get(rec.schema_id, 0), rec.metadata)
        elif isinstance(rec, Message) and rec.channel_id in self.channels:
            self.out.add_message(self.channels[rec.channel_id], rec.log_time, rec.data, rec.publish_time,
                                 rec.sequence)
            self.messages += 1
        elif isinstance(rec, Metadata):
            self.out.add_metadata(rec.name, rec.metadata)
            self.metadata += 1


def repair(src: Path, dst: Path) -> Repaired:
    """Rewrite `src` (an MCAP file, whole or cut) into `dst`: everything up to its last complete record."""
    complete = False
    with open(src, "rb") as fin, open(dst, "wb") as fout:
        out = Writer(fout, compression=CompressionType.LZ4)
        copier = _Copier(out)
        records = StreamReader(fin, skip_magic=False).records
        started = False
        try:
            for rec in records:
                if isinstance(rec, Header):
                    out.start(profile=rec.profile, library=rec.library)
                    started = True
                    continue
                if isinstance(rec, Footer):
                    complete = rec.summary_start != 0
                    break
                copier.record(rec)
        except (McapError, EOFError, ValueError, OSError, RuntimeError):  # the cut: a partial or corrupt record
            pass
        if not started:  # cut inside the header: an empty, whole file
            out.start(profile="", library="")
        out.finish()
    return Repaired(copier.messages, len(copier.channels), copier.metadata, complete)


def main(argv: list[str] | None = None) -> int:
    ap = argparse.ArgumentParser(prog="navig8-log", description=__doc__.split("\n\n")[0])
    sub = ap.add_subparsers(dest="command", required=True)
    rp = sub.add_parser("repair", help="rewrite a log cut by a crash into a whole, indexed MCAP file")
    rp.add_argument("log", type=Path)
    rp.add_argument("-o", "--output", type=Path, default=None, help="default: LOG with .repaired.mcap")
    a = ap.parse_args(argv)
    src: Path = a.log
    dst: Path = a.output or src.with_name(f"{src.stem}.repaired{src.suffix}")
    if dst.resolve() == src.resolve():
        print("navig8-log repair: the output must not be the input", file=sys.stderr)
        return 2
    try:
        with open(src, "rb") as fh:
            if fh.read(8) != b"\x89MCAP0\r\n":
                print(f"navig8-log repair: {src} is not an MCAP file", file=sys.stderr)
                return 1
        got = repair(src, dst)
    except OSError as e:
        print(f"navig8-log repair: {e.strerror or e} ({e.filename or src})", file=sys.stderr)
        return 1
    state = "was whole" if got.input_was_complete else "was cut"
    print(f"{dst}: {got.messages} messages on {got.channels} channels, {got.metadata} metadata records ({src} {state})")
    return 0


if __name__ == "__main__":
    sys.exit(main())

"""navig8-tlog: export the raw MAVLink frames of an MCAP log to a .tlog (pymavlink, MAVExplorer, MAVProxy).

    navig8-tlog run.mcap [--out run.tlog] [--link gcs|api|sim|all] [--direction in|out|both]

A .tlog is a sequence of records: an 8-byte big-endian timestamp in microseconds since the Unix epoch,
then one MAVLink frame. The timestamp is the writer's wall clock when the frame crossed the link. The log
keeps each datagram as it crossed the link (one or more frames back to back); the export splits them.
A truncated MCAP exports up to its last complete chunk.
"""

from __future__ import annotations

import argparse
import struct
from pathlib import Path

from navig8_fc.mavlink.codec import split_frames
from navig8_fc.shell.mcap_log import read_mcap_records


def export(mcap_path: str | Path, out_path: str | Path, link: str = "all", direction: str = "both") -> int:
    n = 0
    with open(out_path, "wb") as out:
        for topic, _t_ns, pub_ns, data in read_mcap_records(mcap_path):
            parts = topic.strip("/").split("/")
            if len(parts) != 3 or parts[0] != "mavlink" or not isinstance(data, (bytes, bytearray)):
                continue
            if link != "all" and parts[1] != link:
                continue
            if parts[2] not in ("in", "out") or (direction != "both" and parts[2] != direction):
                continue
            stamp = struct.pack(">Q", pub_ns // 1000)
            for frame in split_frames(bytes(data))[0]:
                out.write(stamp + frame)
                n += 1
    return n


def main(argv: list[str] | None = None) -> int:
    ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("mcap")
    ap.add_argument("--out", default=None)
    ap.add_argument("--link", default="all", choices=["all", "gcs", "api", "sim"])
    ap.add_argument("--direction", default="both", choices=["both", "in", "out"])
    a = ap.parse_args(argv)
    out = a.out or str(Path(a.mcap).with_suffix(".tlog"))
    n = export(a.mcap, out, a.link, a.direction)
    print(f"{out}: {n} frames")
    return 0


if __name__ == "__main__":
    raise SystemExit(main())

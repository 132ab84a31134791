"""The log-download protocol (navig8_fc.gcs.log_transfer) through pymavlink messages as MAVSDK's LogFiles plugin and
QGroundControl send them, and the log directory it serves (navig8_fc.shell.log_files): a log still being written is
downloaded whole, as it was when listed."""

from __future__ import annotations

from io import BytesIO
from pathlib import Path
from typing import Any

from mcap.reader import make_reader
from pymavlink.dialects.v20 import common as M

from navig8_fc.gcs.ftp_pacing import ReplyBudget, ReplyPacer
from navig8_fc.gcs.log_transfer import LogEntry, LogTransfer, reply_cost
from navig8_fc.gcs.statustext import StatusTextEncoder
from navig8_fc.shell.log_files import LogDirectory
from navig8_fc.shell.mcap_log import McapLogger
from navig8_fc.shell.mcap_writer import PROVISIONAL_END

FAST = ReplyBudget(bytes_per_s=1e9, burst_bytes=1e9, packets_per_poll=10_000)  # pacing out of the way


class Logs:
    """A LogSource over byte strings."""

    def __init__(self, *logs: bytes) -> None:
        self.logs = list(logs)

    def list_logs(self) -> list[LogEntry]:
        return [LogEntry(1_700_000_000 + i, len(b)) for i, b in enumerate(self.logs)]

    def read(self, log_id: int, offset: int, n: int) -> bytes:
        return self.logs[log_id][offset:offset + n]


class Gcs:
    def __init__(self, source: Any, budget: ReplyBudget = FAST) -> None:
        self.veh = M.MAVLink(BytesIO(), srcSystem=1, srcComponent=1)
        self.gcs = M.MAVLink(BytesIO(), srcSystem=245, srcComponent=190)
        self.logs = LogTransfer(self.veh, 1, 1, source, ReplyPacer(budget, cost=reply_cost),
                                StatusTextEncoder(self.veh))
        self.t = 0.0

    def send(self, msg: Any) -> list[Any]:
        got = self.logs.handle(self.veh.decode(bytearray(msg.pack(self.gcs))), "peer", self.t)
        return [self.gcs.decode(bytearray(m.pack(self.veh))) for m in got]

    def run(self, duration_s: float, dt_s: float = 0.001) -> list[Any]:
        out: list[Any] = []
        for _ in range(round(duration_s / dt_s)):
            self.t += dt_s
            out += [self.gcs.decode(bytearray(m.pack(self.veh))) for _src, m in self.logs.poll(self.t)]
        return out

    def download(self, log_id: int, ofs: int = 0, count: int = 0xFFFFFFFF) -> bytes:
        got = self.send(self.gcs.log_request_data_encode(1, 1, log_id, ofs, count)) + self.run(0.05)
        data = bytearray()
        for m in got:
            assert m.get_type() == "LOG_DATA" and m.id == log_id and m.ofs == ofs + len(data)
            data += bytes(m.data[:m.count])
        return bytes(data)


def test_listing_and_downloads_return_every_byte_in_90_byte_packets() -> None:
    a, b = bytes(range(256)) * 40 + b"end", b"x" * 90
    g = Gcs(Logs(a, b))
    entries = g.send(g.gcs.log_request_list_encode(1, 1, 0, 0xFFFF)) + g.run(0.01)
    assert [(e.id, e.num_logs, e.last_log_num, e.size, e.time_utc) for e in entries] == [
        (0, 2, 1, len(a), 1_700_000_000), (1, 2, 1, 90, 1_700_000_001)]
    assert g.download(0) == a and g.download(1) == b
    assert g.download(0, 11520, 11520) == a[11520:23040]  # MAVSDK's chunk of 128 packets
    assert g.download(0, 900, 5) == a[900:905]
    past = g.send(g.gcs.log_request_data_encode(1, 1, 1, 90, 0xFFFFFFFF))  # at the end: one empty packet
    assert [(m.ofs, m.count) for m in past] == [(90, 0)]


def test_no_logs_bad_requests_and_erase() -> None:
    g = Gcs(Logs())
    assert [(e.id, e.num_logs, e.size) for e in g.send(g.gcs.log_request_list_encode(1, 1, 0, 0xFFFF))] == [
        (0, 0, 0)]  # PX4's answer: MAVSDK reports NO_LOGFILES
    logs = Logs(b"abc")
    g = Gcs(logs)
    for msg, text in ((g.gcs.log_request_data_encode(1, 1, 3, 0, 90), "no log 3 (logs 0..0)"),
                      (g.gcs.log_request_list_encode(1, 1, 5, 9), "no log 5..9"),
                      (g.gcs.log_erase_encode(1, 1), "LOG_ERASE refused")):
        got = g.send(msg) + g.run(0.01)
        assert {m.get_type() for m in got} == {"STATUSTEXT"} and text in "".join(m.text for m in got), got
    assert logs.logs == [b"abc"]
    assert g.send(g.gcs.log_request_list_encode(2, 1, 0, 0xFFFF)) == []  # another system's: not ours


def test_replies_are_paced_and_end_stops_the_transfer() -> None:
    """At the default budget (2.5 KB/s, 1.5 KB at once) a 100 KB log draws what the bucket affords, and
    LOG_REQUEST_END stops it."""
    g = Gcs(Logs(bytes(100_000)), ReplyBudget())
    g.send(g.gcs.log_request_list_encode(1, 1, 0, 0xFFFF))
    first = g.send(g.gcs.log_request_data_encode(1, 1, 0, 0, 0xFFFFFFFF))
    got = first + g.run(2.0)
    sent = sum(reply_cost(m) for m in got if m.get_type() == "LOG_DATA")
    assert 0 < sent <= 1500 + 2.0 * 2500 + 109, sent
    g.send(g.gcs.log_request_end_encode(1, 1))
    assert [m for m in g.run(1.0) if m.get_type() == "LOG_DATA"] == []


def test_a_log_being_written_downloads_whole_as_listed(tmp_path: Path) -> None:
    """The sealed log of a running FC: listed, then written on; the download is the file as it was at the
    listing, a whole MCAP file that the library's reader reads with its defaults."""
    log = McapLogger(tmp_path / "run.mcap", chunk_size=2048)
    log.metadata("run", {"scenario": "test"})
    for i in range(200):
        log.log("/x", i * 1000, {"i": i, "pad": "y" * 40})
    g = Gcs(LogDirectory(tmp_path))
    (entry,) = g.send(g.gcs.log_request_list_encode(1, 1, 0, 0xFFFF))
    for i in range(200, 400):  # the flight goes on: more chunks over the provisional end
        log.log("/x", i * 1000, {"i": i, "pad": "y" * 40})
    data = g.download(0)
    log.close()
    assert len(data) == entry.size
    out = tmp_path / "downloaded.mcap"
    out.write_bytes(data)
    with out.open("rb") as fh:
        got = [m.log_time for _s, _c, m in make_reader(fh).iter_messages()]
    assert got and got == sorted(got) and len(got) < 400
    stable = len(data) - len(PROVISIONAL_END)  # the finished file has its real end where the provisional one was
    assert data[:stable] == (tmp_path / "run.mcap").read_bytes()[:stable] and data[stable:] == PROVISIONAL_END
